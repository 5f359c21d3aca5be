// The floating toolbar: tool modes, edit operations, undo/redo (enabled as the stacks allow), the camera panel
// and help.
import { h } from "../dom.js";

/**
 * @param {{tools: import("./tools.js").Tools, ops: import("./operations.js").Operations,
 *   sync: import("./sync.js").Sync, history: import("./history.js").History, help: () => void,
 *   cameras: import("./camera-panel.js").CameraPanel}} c
 */
export function buildToolbar(c) {
  const modeButtons = [
    ["select", "↖", "Select (S)"],
    ["divider", "┄", "Draw divider (D)"],
    ["boundary", "▁", "Draw boundary (B)"],
    ["ped_crossing", "▦", "Draw crosswalk (C)"],
  ].map(([mode, icon, title]) =>
    h("button.tool", { title, "aria-label": title, dataset: { mode }, onclick: () => c.tools.setMode(mode) }, h("span.icon", {}, icon), h("span.tool-label", {}, title.split(" (")[0].replace("Draw ", ""))),
  );
  const syncModes = () => {
    for (const button of modeButtons) button.classList.toggle("active", button.dataset.mode === c.tools.mode);
  };
  c.tools.addEventListener("mode", syncModes);
  syncModes();
  const op = (icon, title, run, id) => h(`button.tool${id ? `#${id}` : ""}`, { title, "aria-label": title, onclick: run }, h("span.icon", {}, icon));
  const undo = op("↶", "Undo (Ctrl+Z)", () => c.sync.undo(), "undo");
  const redo = op("↷", "Redo (Ctrl+Shift+Z)", () => c.sync.redo(), "redo");
  const syncHistory = () => {
    undo.disabled = !c.history.undoStack.length;
    redo.disabled = !c.history.redoStack.length;
  };
  c.history.addEventListener("change", syncHistory);
  syncHistory();
  const tolerance = h("input.tolerance#simplify-tolerance", {
    type: "number",
    min: 0.01,
    max: 5,
    step: 0.05,
    value: c.ops.simplifyToleranceM,
    title: "Simplify tolerance, metres",
    onchange: (event) => {
      const value = Number(event.target.value);
      if (value > 0) c.ops.simplifyToleranceM = value;
    },
  });
  const cameraButton = op("◫", "Camera views (⇧C)", () => c.cameras.toggle(), "camera-button");
  cameraButton.setAttribute("aria-pressed", "false");
  c.cameras.element.addEventListener("camera-toggle", () => {
    cameraButton.classList.toggle("active", c.cameras.open);
    cameraButton.setAttribute("aria-pressed", String(c.cameras.open));
  });
  return h(
    "div.toolbar",
    { role: "toolbar" },
    h("div.tool-group", {}, ...modeButtons),
    h(
      "div.tool-group",
      {},
      op("⇄", "Reverse direction (V)", () => c.ops.reverse()),
      op("✂", "Split at vertex under cursor (K)", () => c.ops.split()),
      op("⊕", "Merge two polylines (M)", () => c.ops.merge()),
      op("≈", "Simplify (G)", () => c.ops.simplify()),
      tolerance,
      h("span.unit", {}, "m"),
      op("✕", "Delete element (Del)", () => c.ops.deleteSelected()),
    ),
    h("div.tool-group", {}, undo, redo),
    h("div.tool-group", {}, cameraButton, op("?", "Keyboard shortcuts (?)", c.help, "help-button")),
  );
}
