// The editor's keyboard shortcuts (one table for handling and for the help overlay).

/**
 * @param {{tools: import("./tools.js").Tools, ops: import("./operations.js").Operations,
 *   sync: import("./sync.js").Sync, review: import("./review-panel.js").ReviewPanel,
 *   findings: import("./findings.js").Findings, view: import("ol/View.js").default,
 *   side: {show: (name: string) => void}, help: () => void,
 *   cameras: import("./camera-panel.js").CameraPanel}} c
 * @returns {import("./shortcuts.js").Shortcut[]}
 */
export function editorShortcuts(c) {
  const drawing = () => c.tools.mode !== "select";
  const escape = () => {
    if (document.getElementById("help-overlay")) c.help();
    else if (c.cameras.closeEnlarged()) return;
    else if (drawing()) {
      c.tools.abortDrawing();
      c.tools.setMode("select");
    } else c.tools.setSelection([]);
  };
  return [
    { keys: ["s"], label: "Select / edit mode", group: "Tools", run: () => c.tools.setMode("select") },
    { keys: ["d"], label: "Draw a divider", group: "Tools", run: () => c.tools.setMode("divider") },
    { keys: ["b"], label: "Draw a boundary", group: "Tools", run: () => c.tools.setMode("boundary") },
    { keys: ["c"], label: "Draw a crosswalk polygon", group: "Tools", run: () => c.tools.setMode("ped_crossing") },
    { keys: ["Enter"], label: "Finish the drawing", group: "Tools", run: () => c.tools.finishDrawing() },
    { keys: ["Escape"], label: "Cancel drawing / clear selection / close help", group: "Tools", run: escape },
    { keys: ["1"], label: "Relabel as divider", group: "Edit", run: () => c.ops.relabel("divider") },
    { keys: ["2"], label: "Relabel as crosswalk", group: "Edit", run: () => c.ops.relabel("ped_crossing") },
    { keys: ["3"], label: "Relabel as boundary", group: "Edit", run: () => c.ops.relabel("boundary") },
    { keys: ["v"], label: "Reverse direction", group: "Edit", run: () => c.ops.reverse() },
    { keys: ["k"], label: "Split at the vertex under the cursor", group: "Edit", run: () => c.ops.split() },
    { keys: ["m"], label: "Merge two selected polylines", group: "Edit", run: () => c.ops.merge() },
    { keys: ["g"], label: "Simplify (Douglas-Peucker)", group: "Edit", run: () => c.ops.simplify() },
    {
      keys: ["Delete", "Backspace"],
      label: "Delete element (while drawing: last point)",
      group: "Edit",
      run: () => (drawing() ? c.tools.undoLastPoint() : c.ops.deleteSelected()),
    },
    { keys: ["Mod+z"], label: "Undo", group: "Edit", run: () => c.sync.undo() },
    { keys: ["Mod+Shift+z", "Mod+y"], label: "Redo", group: "Edit", run: () => c.sync.redo() },
    { keys: ["a"], label: "Accept (unchanged)", group: "Review", run: () => c.ops.review("accepted") },
    { keys: ["f"], label: "Mark fixed (changed)", group: "Review", run: () => c.ops.review("fixed") },
    { keys: ["x"], label: "Reject", group: "Review", run: () => c.ops.review("rejected") },
    { keys: ["Shift+a"], label: "Approve (leads)", group: "Review", run: () => c.ops.review("approved") },
    { keys: ["Shift+r"], label: "Return to annotator (leads)", group: "Review", run: () => c.ops.review("returned") },
    { keys: ["n"], label: "Next item of my queue", group: "Review", run: () => c.review.next() },
    { keys: ["Shift+n"], label: "Next region of my queue", group: "Review", run: () => c.review.nextRegion() },
    { keys: ["."], label: "Next element of the region to review", group: "Review", run: () => c.review.region.step(1) },
    { keys: [","], label: "Previous element of the region to review", group: "Review", run: () => c.review.region.step(-1) },
    { keys: ["]"], label: "Next finding / issue", group: "Findings", run: () => (c.side.show("Findings"), c.findings.step(1)) },
    { keys: ["["], label: "Previous finding / issue", group: "Findings", run: () => (c.side.show("Findings"), c.findings.step(-1)) },
    { keys: ["Shift+c"], label: "Camera panel: the images that see the selection", group: "Cameras", run: () => c.cameras.toggle() },
    { keys: ["Shift+v"], label: "Images of the map point under the cursor", group: "Cameras", run: () => c.cameras.pointViews(c.ops.cursor) },
    { keys: ["Shift+m"], label: "Lane-mask overlay in the images", group: "Cameras", run: () => c.cameras.toggleMask() },
    { keys: ["}"], label: "Next images along the element", group: "Cameras", run: () => c.cameras.step(1) },
    { keys: ["{"], label: "Previous images along the element", group: "Cameras", run: () => c.cameras.step(-1) },
    { keys: ["l"], label: "Show the layers panel", group: "View", run: () => c.side.show("Layers") },
    { keys: ["+", "="], label: "Zoom in", group: "View", run: () => c.view.animate({ zoom: (c.view.getZoom() || 0) + 1, duration: 150 }) },
    { keys: ["-"], label: "Zoom out", group: "View", run: () => c.view.animate({ zoom: (c.view.getZoom() || 0) - 1, duration: 150 }) },
    { keys: ["?"], label: "This help", group: "View", run: c.help },
  ];
}
