// The editor view: loads a site, builds the map and its panels (the camera panel beside the map), and wires
// tools, autosave, undo/redo, findings and keyboard shortcuts together.
import { h, replaceChildren, toast } from "../dom.js";
import { ConflictBanner } from "./conflicts.js";
import { ElementStore, pointsOf } from "./elements.js";
import { Findings } from "./findings.js";
import { History } from "./history.js";
import { layersPanel } from "./layers-panel.js";
import { createMap, fitSite } from "./map.js";
import { Operations } from "./operations.js";
import { ReviewPanel } from "./review-panel.js";
import { Shortcuts } from "./shortcuts.js";
import { StatusBar } from "./statusbar.js";
import { Sync } from "./sync.js";
import { Tools } from "./tools.js";
import { CLASS_LABELS } from "./styles.js";
import { editorShortcuts } from "./keymap.js";
import { buildToolbar } from "./toolbar.js";
import { CameraPanel } from "./camera-panel.js";
import { ReprojectionFigures } from "./reprojection.js";

/**
 * Load the site's description, rasters and elements (a site whose rasters cannot be tiled still opens).
 * @param {import("../api.js").Api} api
 * @param {number} siteId
 */
async function loadSite(api, siteId) {
  const base = `/api/sites/${siteId}`;
  const layersOrNone = api.get(`${base}/layers`).catch((error) => {
    toast(`Raster layers unavailable, editing vectors only: ${error.message}`, "error");
    return [];
  });
  const [site, layers, elements] = await Promise.all([api.get(base), layersOrNone, api.get(`${base}/elements`, { limit: 100000 })]);
  return { site, layers, elements };
}

/** Sidebar with tabs (Review, Layers, Findings). */
function sidebar(panels) {
  const body = h("div.sidebar-body");
  const tabs = h("div.sidebar-tabs");
  const show = (name) => {
    for (const button of tabs.children) button.classList.toggle("active", button.dataset.tab === name);
    replaceChildren(body, panels[name]);
  };
  for (const name of Object.keys(panels)) {
    tabs.appendChild(h("button.sidebar-tab", { dataset: { tab: name }, onclick: () => show(name) }, name));
  }
  show(Object.keys(panels)[0]);
  return { element: h("aside.sidebar", {}, tabs, body), show };
}

/**
 * @param {HTMLElement} container
 * @param {import("../api.js").Api} api
 * @param {number} siteId
 * @param {URLSearchParams} params ?element=ID centres and selects an element
 */
export async function mountEditor(container, api, siteId, params) {
  const loading = h("div.center-page", {}, h("p.muted", {}, "Loading site…"));
  container.appendChild(loading);
  let data;
  try {
    data = await loadSite(api, siteId);
  } catch (error) {
    replaceChildren(loading, h("p.form-error", { role: "alert" }, `Cannot open site ${siteId}: ${error.message}`));
    return { destroy() {} };
  }
  loading.remove();
  const isLead = api.me.role !== "annotator";
  const mapTarget = h("div.map#map", { tabindex: 0 });
  const mapWrap = h("div.map-wrap", {}, mapTarget);
  const statusBar = new StatusBar(api, siteId);
  const root = h("div.editor", {}, mapWrap, statusBar.element);
  container.appendChild(root);

  const m = createMap(mapTarget, api, data.site, data.layers);
  const store = new ElementStore(m.elementSource);
  store.load(data.elements);
  const history = new History();
  const sync = new Sync(api, siteId, store, history);
  const tools = new Tools(m.map, m.elementLayer, store, sync);
  const ops = new Operations(tools, store, sync);
  const findings = new Findings({ api, siteId, source: m.findingSource, view: m.view, store, tools, isLead });
  const figures = new ReprojectionFigures(api, siteId);
  const review = new ReviewPanel({ api, siteId, view: m.view, store, tools, ops, isLead, regionSource: m.regionSource, figures });
  const onToggle = (open) => {
    root.classList.toggle("cameras-open", open);
    m.map.updateSize();
  };
  const cameras = new CameraPanel({ api, siteId, store, tools, sync, figures, onToggle });
  root.insertBefore(cameras.element, statusBar.element);
  const conflicts = new ConflictBanner(sync, m.draftSource);
  const overlays = [
    { title: "Vector elements", layer: m.elementLayer },
    { title: "Findings and issues", layer: m.map.getLayers().getArray().at(-1) },
  ];
  const side = sidebar({ Review: review.element, Layers: layersPanel(m.rasters, overlays), Findings: findings.element });
  root.insertBefore(side.element, mapWrap);
  fitSite(m);
  const shortcuts = new Shortcuts(editorShortcuts({ tools, ops, sync, review, findings, view: m.view, side, cameras, help: () => shortcuts.toggleHelp() }));
  mapWrap.appendChild(buildToolbar({ tools, ops, sync, history, cameras, help: () => shortcuts.toggleHelp() }));
  mapWrap.appendChild(conflicts.element);
  const title = h("div.site-title", {}, h("strong", {}, data.site.name), h("span.muted", {}, ` #${siteId}`));
  mapWrap.appendChild(title);

  wireStatus({ m, store, sync, tools, ops, review, statusBar, findings });
  m.elementSource.on("removefeature", (event) => tools.select.getFeatures().remove(event.feature));
  exposeTestHook({ m, siteId, cameras });
  findings.refresh();
  focusRequested(params, store, m.view, tools);
  return {
    destroy() {
      shortcuts.destroy();
      cameras.closeEnlarged();
      statusBar.destroy();
      review.release();
      m.map.setTarget(undefined);
      delete window.camaEditor;
    },
  };
}

/** Keep the status bar, selection panel and lint in step with the map and autosave. */
function wireStatus({ m, store, sync, tools, ops, review, statusBar, findings }) {
  let lintTimer = 0;
  m.map.on("pointermove", (event) => {
    ops.cursor = event.coordinate;
    statusBar.pointer(event.coordinate);
  });
  m.view.on("change:resolution", () => statusBar.setScale(m.view.getResolution()));
  statusBar.setScale(m.view.getResolution());
  const showMode = () => statusBar.setMode(tools.mode === "select" ? "Select / edit" : `Drawing ${CLASS_LABELS[tools.mode].toLowerCase()} (Enter finishes, Esc cancels)`);
  tools.addEventListener("mode", showMode);
  showMode();
  tools.addEventListener("selection", () => {
    const ids = tools.selected().map((feature) => feature.getId());
    statusBar.setSelection(ids.length);
    review.update();
    window.dispatchEvent(new CustomEvent("cama:selection", { detail: { ids } })); // the top bar's 3D review link
  });
  const count = () => statusBar.setCount(m.elementSource.getFeatures().length);
  m.elementSource.on(["addfeature", "removefeature"], count);
  count();
  sync.addEventListener("status", () => statusBar.setSave(sync.status));
  sync.addEventListener("changed", () => {
    review.update();
    clearTimeout(lintTimer);
    lintTimer = setTimeout(() => findings.refresh(), 800);
  });
}

/** `#/site/N?element=ID` (from the lead queue): centre on and select that element. */
function focusRequested(params, store, view, tools) {
  const id = Number(params.get("element"));
  if (!id) return;
  const feature = store.feature(id);
  if (!feature) {
    toast(`Element #${id} is not on this site (or deleted)`, "error");
    return;
  }
  view.fit(feature.getGeometry().getExtent(), { padding: [120, 120, 120, 120], minResolution: 0.05 });
  tools.setSelection([feature]);
}

/**
 * A small hook for the browser tests and the bench: map pixel of a site point, element count, an element's points
 * as the map draws them, when the elements
 * were first drawn and when all visible tiles were, (while `recording`) each frame's render time in ms, and what
 * the camera panel shows.
 */
function exposeTestHook({ m, siteId, cameras }) {
  const hook = {
    siteId,
    firstRenderMs: null,
    renderCompleteMs: null,
    recording: false,
    frameRenderMs: [],
    pixelOf: (x, y) => m.map.getPixelFromCoordinate([x, y]),
    elementCount: () => m.elementSource.getFeatures().length,
    pointsOf: (id) => {
      const feature = m.elementSource.getFeatureById(id);
      return feature ? pointsOf(feature) : null;
    },
    cameras: () => cameras.describe(),
    regionOutlines: () => m.regionSource.getFeatures().map((feature) => feature.getGeometry().getExtent()),
    centerOn: (x, y, resolution) => {
      m.view.setCenter([x, y]);
      if (resolution) m.view.setResolution(resolution);
      m.map.renderSync();
    },
  };
  m.elementLayer.once("postrender", () => {
    hook.firstRenderMs = performance.now();
  });
  m.map.once("rendercomplete", () => {
    hook.renderCompleteMs = performance.now();
  });
  let frameStart = 0;
  m.map.on("precompose", () => {
    frameStart = performance.now();
  });
  m.map.on("postcompose", () => {
    if (hook.recording) hook.frameRenderMs.push(performance.now() - frameStart);
  });
  window.camaEditor = hook;
}
