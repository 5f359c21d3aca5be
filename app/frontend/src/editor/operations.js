// Edit operations on the selection beyond what Modify does: delete, relabel, reverse, split, merge, simplify.
// Each builds the new content and saves it as one undoable transaction; the map follows the server's answer.
import LineString from "ol/geom/LineString.js";
import { toast } from "../dom.js";
import { pointsOf } from "./elements.js";
import { CLASS_LABELS } from "./styles.js";

const CLOSED_TOLERANCE_M = 0.05;
const JOIN_TOLERANCE_M = 0.01;

const dist = (a, b) => Math.hypot(a[0] - b[0], a[1] - b[1]);

/**
 * Points for an element of class `cls` made from another element's points: a crosswalk needs a closed ring
 * (from a polyline whose ends meet), a polyline drops the closing point of a ring. Null when impossible.
 * @param {number[][]} points
 * @param {string} fromCls
 * @param {string} toCls
 */
export function convertPoints(points, fromCls, toCls) {
  const fromRing = fromCls === "ped_crossing";
  const toRing = toCls === "ped_crossing";
  if (fromRing === toRing) return points;
  if (fromRing) return points.slice(0, -1);
  const closed = dist(points[0], points[points.length - 1]) <= CLOSED_TOLERANCE_M;
  if (points.length < 3) return null;
  return closed ? [...points.slice(0, -1), points[0]] : null;
}

/**
 * Join two polylines end to start, reversing either so that the nearest ends meet; a shared end point is
 * kept once.
 * @param {number[][]} a
 * @param {number[][]} b
 */
export function mergePolylines(a, b) {
  const options = [
    [a, b],
    [a, [...b].reverse()],
    [[...a].reverse(), b],
    [[...a].reverse(), [...b].reverse()],
  ];
  let best = options[0];
  for (const option of options) {
    if (dist(option[0].at(-1), option[1][0]) < dist(best[0].at(-1), best[1][0])) best = option;
  }
  const [first, second] = best;
  const joined = dist(first.at(-1), second[0]) <= JOIN_TOLERANCE_M ? second.slice(1) : second;
  return [...first, ...joined];
}

/**
 * Split a polyline at its interior vertex nearest `coordinate`: [head, tail] sharing that vertex, or null.
 * @param {number[][]} points
 * @param {number[]} coordinate
 */
export function splitPolyline(points, coordinate) {
  let index = -1;
  let best = Infinity;
  for (let i = 1; i < points.length - 1; i += 1) {
    const d = dist(points[i], coordinate);
    if (d < best) {
      best = d;
      index = i;
    }
  }
  return index < 0 ? null : [points.slice(0, index + 1), points.slice(index)];
}

/**
 * Douglas-Peucker simplification of a polyline (OpenLayers' LineString.simplify) with a metre tolerance.
 * @param {number[][]} points
 * @param {number} toleranceM
 */
export function simplifyPolyline(points, toleranceM) {
  const simplified = /** @type {LineString} */ (new LineString(points).simplify(toleranceM));
  return simplified.getCoordinates().map((c) => [c[0], c[1]]);
}

export class Operations {
  /**
   * @param {import("./tools.js").Tools} tools
   * @param {import("./elements.js").ElementStore} store
   * @param {import("./sync.js").Sync} sync
   */
  constructor(tools, store, sync) {
    this.tools = tools;
    this.store = store;
    this.sync = sync;
    /** Last pointer position on the map (site metres), where split cuts. */
    this.cursor = null;
    this.simplifyToleranceM = 0.2;
  }

  /** The selected elements, or a hint and [] when nothing is selected. */
  selectedElements() {
    const elements = this.tools.selected().map((f) => this.store.get(/** @type {number} */ (f.getId())));
    if (!elements.length) toast("Select an element first (click it; shift-click adds more)");
    return elements;
  }

  deleteSelected() {
    const elements = this.selectedElements();
    if (!elements.length) return;
    this.tools.setSelection([]);
    const label = elements.length === 1 ? "Delete element" : `Delete ${elements.length} elements`;
    this.sync.commit(label, elements.map((e) => ({ op: "delete", id: e.id })));
  }

  /** Change the class of the selection (number keys). */
  relabel(cls) {
    const steps = [];
    for (const element of this.selectedElements()) {
      if (element.class === cls) continue;
      const points = convertPoints(pointsOf(this.store.feature(element.id)), element.class, cls);
      if (!points) {
        toast(`#${element.id}: a crosswalk needs a closed outline; draw one with C`, "error");
        continue;
      }
      steps.push({ op: "update", id: element.id, body: { class: cls, points } });
    }
    if (steps.length) this.sync.commit(`Relabel as ${CLASS_LABELS[cls].toLowerCase()}`, steps);
  }

  /** Reverse the direction of the selection. */
  reverse() {
    const steps = this.selectedElements().map((element) => ({
      op: "update",
      id: element.id,
      body: { points: [...element.points].reverse() },
    }));
    if (steps.length) this.sync.commit("Reverse direction", steps);
  }

  /** Split the one selected polyline at the vertex nearest the cursor into two elements of its class. */
  async split() {
    const elements = this.selectedElements();
    if (elements.length !== 1 || elements[0].class === "ped_crossing") {
      if (elements.length) toast("Split needs exactly one selected polyline", "error");
      return;
    }
    const element = elements[0];
    const parts = this.cursor ? splitPolyline(element.points, this.cursor) : null;
    if (!parts) {
      toast("Split: point at an interior vertex of the selected polyline", "error");
      return;
    }
    const records = await this.sync.commit("Split polyline", [
      { op: "update", id: element.id, body: { points: parts[0] } },
      { op: "create", body: { class: element.class, points: parts[1] } },
    ]);
    if (records) this.tools.setSelection(records.map((r) => this.store.feature(r.id)));
  }

  /** Merge two selected polylines into the first one (the second is deleted). */
  async merge() {
    const elements = this.selectedElements();
    if (elements.length !== 2 || elements.some((e) => e.class === "ped_crossing")) {
      if (elements.length) toast("Merge needs exactly two selected polylines", "error");
      return;
    }
    const [keep, drop] = elements;
    const points = mergePolylines(keep.points, drop.points);
    const records = await this.sync.commit("Merge polylines", [
      { op: "update", id: keep.id, body: { points } },
      { op: "delete", id: drop.id },
    ]);
    if (records) this.tools.setSelection([this.store.feature(keep.id)]);
  }

  /** Simplify the selected polylines (Douglas-Peucker at the set tolerance). */
  simplify() {
    const steps = [];
    for (const element of this.selectedElements()) {
      if (element.class === "ped_crossing") continue;
      const points = simplifyPolyline(element.points, this.simplifyToleranceM);
      if (points.length < element.points.length) steps.push({ op: "update", id: element.id, body: { points } });
    }
    if (steps.length) this.sync.commit("Simplify", steps);
    else toast("Nothing to simplify at this tolerance");
  }

  /** Review the selection: accepted, fixed or rejected (leads also approved or returned). */
  review(state) {
    const steps = this.selectedElements().map((e) => ({ op: "review", id: e.id, state }));
    if (steps.length) this.sync.commit(`Mark ${state}`, steps);
  }
}
