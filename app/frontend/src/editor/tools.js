// Editing interactions: Select (shift toggles), Modify on the selection (drag a vertex, drag a segment to insert
// one, alt-click deletes one), Translate on the selection (Ctrl/Cmd-drag moves the selected elements whole), Draw
// for new polylines and crosswalk polygons, Snap to existing vertices (last).
import Draw from "ol/interaction/Draw.js";
import Modify from "ol/interaction/Modify.js";
import Select from "ol/interaction/Select.js";
import Snap from "ol/interaction/Snap.js";
import Translate from "ol/interaction/Translate.js";
import {
  altKeyOnly,
  click,
  doubleClick,
  platformModifierKeyOnly,
  primaryAction,
  shiftKeyOnly,
  singleClick,
} from "ol/events/condition.js";
import { geometryFor, pointsOf, samePoints } from "./elements.js";
import { CLASS_COLORS, CLASS_LABELS, selectedStyle } from "./styles.js";
import { Stroke, Style, Circle, Fill } from "ol/style.js";

const CLICK_INSERT_TOLERANCE_M = 0.01;

/** Distance from p to segment ab, metres. */
function segmentDistance(p, a, b) {
  const dx = b[0] - a[0];
  const dy = b[1] - a[1];
  const t = Math.max(0, Math.min(1, ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / (dx * dx + dy * dy || 1)));
  return Math.hypot(p[0] - a[0] - t * dx, p[1] - a[1] - t * dy);
}

/**
 * True when `points` is `old` plus vertices that lie on its segments: what Modify leaves after a plain click on
 * a selected line (it inserts on press); such a click is a selection, not an edit.
 */
export function onlyClickInserts(points, old) {
  if (points.length <= old.length) return false;
  const kept = points.filter((p, i) => {
    const isOld = old.some((q) => Math.abs(p[0] - q[0]) < 1e-6 && Math.abs(p[1] - q[1]) < 1e-6);
    return isOld || i === 0 || i === points.length - 1 || segmentDistance(p, points[i - 1], points[i + 1]) > CLICK_INSERT_TOLERANCE_M;
  });
  return samePoints(kept, old);
}

/**
 * Alt-click deletes a vertex. OpenLayers calls a click "single" only when no second click follows within 250 ms,
 * and pairs any two clicks in that window into a "double" one, even with a drag between them: the click that
 * selected a line, a quick vertex drag and an Alt-click come out as a double click when the page is busy, and the
 * deletion was lost. So an Alt double click deletes too. An Alt press never inserts a vertex (see the Modify's
 * insertVertexCondition), so there is no just-inserted vertex for it to remove.
 * @param {import("ol/MapBrowserEvent.js").default} event
 */
function altClickDeletes(event) {
  return altKeyOnly(event) && (singleClick(event) || doubleClick(event));
}

/** The sketch style while drawing a class. */
function sketchStyle(cls) {
  const color = CLASS_COLORS[cls];
  return new Style({
    stroke: new Stroke({ color, width: 3, lineDash: [6, 4] }),
    fill: new Fill({ color: "rgba(232, 121, 249, 0.12)" }),
    image: new Circle({ radius: 5, fill: new Fill({ color }), stroke: new Stroke({ color: "#0f172a", width: 1 }) }),
  });
}

export class Tools extends EventTarget {
  /**
   * @param {import("ol/Map.js").default} map
   * @param {import("ol/layer/Vector.js").default} elementLayer
   * @param {import("./elements.js").ElementStore} store
   * @param {import("./sync.js").Sync} sync
   */
  constructor(map, elementLayer, store, sync) {
    super();
    this.map = map;
    this.store = store;
    this.sync = sync;
    this.mode = "select";
    /** @type {Draw|null} */
    this.draw = null;
    this.select = new Select({
      layers: [elementLayer],
      style: selectedStyle,
      hitTolerance: 6,
      condition: click,
      toggleCondition: shiftKeyOnly,
    });
    this.modify = new Modify({
      features: this.select.getFeatures(),
      pixelTolerance: 10,
      deleteCondition: altClickDeletes,
      insertVertexCondition: (event) => !altKeyOnly(event),
      // Ctrl/Cmd-drag belongs to the Translate below, even on a vertex
      condition: (event) => primaryAction(event) && !platformModifierKeyOnly(event),
    });
    // An element the rasters show beside where it is proposed (a shifted lane line) is moved in one drag, not
    // vertex by vertex: Ctrl/Cmd-drag on a selected element moves every selected element by the same offset.
    this.translate = new Translate({
      features: this.select.getFeatures(),
      condition: (event) => platformModifierKeyOnly(event),
      hitTolerance: 6,
    });
    this.snap = new Snap({ source: elementLayer.getSource(), pixelTolerance: 10 });
    /** @type {Map<number, number[][]>} each feature's points when the current Modify or Translate gesture began */
    this.beforeModify = new Map();
    const remember = (event) => {
      this.beforeModify = new Map(event.features.getArray().map((f) => [/** @type {number} */ (f.getId()), pointsOf(f)]));
    };
    this.modify.on("modifystart", remember);
    this.modify.on("modifyend", (event) => this.saveModified(event.features.getArray()));
    // Snap would pull the pointer onto the moving element's own vertices: off while an element moves
    this.translate.on("translatestart", (event) => {
      remember(event);
      this.snap.setActive(false);
    });
    this.translate.on("translateend", (event) => {
      this.snap.setActive(true);
      this.saveModified(event.features.getArray(), "Move element");
    });
    this.select.on("select", () => this.emit("selection"));
    map.addInteraction(this.select);
    map.addInteraction(this.translate);
    map.addInteraction(this.modify);
    map.addInteraction(this.snap);
  }

  emit(type) {
    this.dispatchEvent(new Event(type));
  }

  /** The selected features. */
  selected() {
    return this.select.getFeatures().getArray().slice();
  }

  /** Select exactly these features. */
  setSelection(features) {
    const collection = this.select.getFeatures();
    collection.clear();
    for (const feature of features) if (feature) collection.push(feature);
    this.emit("selection");
  }

  /**
   * Save the geometry of features the Modify (or Translate: `movedLabel`) interaction changed, named by what
   * happened to the vertices (or by `movedLabel`). The
   * change is judged against the feature as the gesture found it, not against the server's last answer: while an
   * earlier edit of the element is still being saved, that answer is one edit behind (an Alt-click deleting the
   * vertex just dragged in would otherwise look like no change and be lost).
   */
  saveModified(features, movedLabel = "") {
    const steps = [];
    let delta = 0;
    for (const feature of features) {
      const id = /** @type {number} */ (feature.getId());
      const element = this.store.get(id);
      if (!element) continue;
      const before = this.beforeModify.get(id) || element.points;
      const points = pointsOf(feature);
      if (samePoints(points, before)) continue;
      if (onlyClickInserts(points, before)) {
        feature.setGeometry(geometryFor(element.class, before)); // as the click found it, pending saves included
        continue;
      }
      delta += points.length - before.length;
      steps.push({ op: "update", id: element.id, body: { points } });
    }
    if (!steps.length) return;
    const label = movedLabel || (delta > 0 ? "Insert vertex" : delta < 0 ? "Delete vertex" : "Move vertex");
    this.sync.commit(label, steps);
  }

  /**
   * Switch between selecting/editing and drawing a class.
   * @param {"select"|"divider"|"boundary"|"ped_crossing"} mode
   */
  setMode(mode) {
    if (this.draw) {
      this.map.removeInteraction(this.draw);
      this.draw = null;
    }
    this.mode = mode;
    const drawing = mode !== "select";
    this.select.setActive(!drawing);
    this.modify.setActive(!drawing);
    this.translate.setActive(!drawing);
    if (drawing) {
      this.setSelection([]);
      this.draw = new Draw({
        type: mode === "ped_crossing" ? "Polygon" : "LineString",
        style: sketchStyle(mode),
        stopClick: true,
      });
      this.draw.on("drawend", (event) => this.saveDrawn(mode, event.feature));
      this.map.addInteraction(this.draw);
      // Snap must come after Draw to see its pointer events first.
      this.map.removeInteraction(this.snap);
      this.map.addInteraction(this.snap);
    }
    this.emit("mode");
  }

  /** Create the drawn element, then select it and go back to select mode. */
  async saveDrawn(cls, feature) {
    const points = pointsOf(feature);
    setTimeout(() => this.setMode("select"), 0);
    const records = await this.sync.commit(`Draw ${CLASS_LABELS[cls].toLowerCase()}`, [
      { op: "create", body: { class: cls, points } },
    ]);
    if (records) this.setSelection([this.store.feature(records[0].id)]);
  }

  /** Finish the sketch in progress (Enter), or drop its last point (Backspace), or abort it (Escape). */
  finishDrawing() {
    if (this.draw) this.draw.finishDrawing();
  }

  undoLastPoint() {
    if (this.draw) this.draw.removeLastPoint();
  }

  abortDrawing() {
    if (this.draw) this.draw.abortDrawing();
  }
}
