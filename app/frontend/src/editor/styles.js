// Vector styles: colour by class, dash by confidence (low confidence stands out with a halo), state as tint.
import { Circle, Fill, RegularShape, Stroke, Style } from "ol/style.js";
import Point from "ol/geom/Point.js";
import MultiPoint from "ol/geom/MultiPoint.js";

export const CLASS_COLORS = {
  divider: "#38bdf8",
  ped_crossing: "#e879f9",
  boundary: "#f87171",
};
export const CLASS_LABELS = { divider: "Divider", ped_crossing: "Crosswalk", boundary: "Boundary" };
export const LOW_CONFIDENCE = 0.5;
export const HIGH_CONFIDENCE = 0.8;

/**
 * Confidence bucket: "human" (none), "high", "mid" or "low".
 * @param {number|null} confidence
 */
export function confidenceBucket(confidence) {
  if (confidence === null || confidence === undefined) return "human";
  if (confidence >= HIGH_CONFIDENCE) return "high";
  return confidence >= LOW_CONFIDENCE ? "mid" : "low";
}

const DASHES = { human: undefined, high: undefined, mid: [10, 5], low: [4, 5] };
const cache = new Map();

/** Hex colour with alpha. */
function rgba(hex, alpha) {
  const n = parseInt(hex.slice(1), 16);
  return `rgba(${(n >> 16) & 255}, ${(n >> 8) & 255}, ${n & 255}, ${alpha})`;
}

/**
 * The cached styles of an element: class colour, confidence dash, a halo for low confidence,
 * dimmed when reviewed, grey dotted when rejected.
 * @param {string} cls
 * @param {string} bucket
 * @param {string} state
 */
function baseStyles(cls, bucket, state) {
  const key = `${cls}|${bucket}|${state}`;
  let styles = cache.get(key);
  if (styles) return styles;
  const rejected = state === "rejected";
  const reviewed = ["accepted", "fixed", "approved"].includes(state);
  const color = rejected ? "#9ca3af" : CLASS_COLORS[cls] || "#ffffff";
  const alpha = reviewed ? 0.75 : 1;
  styles = [];
  if (bucket === "low" && !rejected) {
    styles.push(new Style({ stroke: new Stroke({ color: "rgba(251, 146, 60, 0.55)", width: 9 }) }));
  }
  styles.push(
    new Style({
      stroke: new Stroke({
        color: rgba(color, alpha),
        width: reviewed ? 2 : 3,
        lineDash: rejected ? [2, 6] : DASHES[bucket],
      }),
      fill: cls === "ped_crossing" ? new Fill({ color: rgba(color, 0.15) }) : undefined,
    }),
  );
  cache.set(key, styles);
  return styles;
}

const vertexStyle = new Style({
  image: new Circle({
    radius: 4,
    fill: new Fill({ color: "#ffffff" }),
    stroke: new Stroke({ color: "#0f172a", width: 1.5 }),
  }),
  geometry: (feature) => {
    const geometry = feature.getGeometry();
    const coordinates = geometry.getType() === "Polygon" ? geometry.getCoordinates()[0] : geometry.getCoordinates();
    return new MultiPoint(coordinates);
  },
});

/** An arrow head at the end of a polyline, showing its direction. */
function arrowStyle(feature, color) {
  const geometry = feature.getGeometry();
  const coordinates = geometry.getType() === "Polygon" ? geometry.getCoordinates()[0] : geometry.getCoordinates();
  if (coordinates.length < 2) return null;
  const end = coordinates[coordinates.length - 1];
  const before = coordinates[coordinates.length - 2];
  const angle = Math.atan2(end[1] - before[1], end[0] - before[0]);
  return new Style({
    geometry: new Point(end),
    image: new RegularShape({
      points: 3,
      radius: 8,
      rotation: Math.PI / 2 - angle,
      fill: new Fill({ color }),
      stroke: new Stroke({ color: "#0f172a", width: 1 }),
    }),
  });
}

/** Style function of the element layer. */
export function elementStyle(feature) {
  const element = feature.get("element");
  return baseStyles(element.class, confidenceBucket(element.confidence), element.state);
}

/** Style of selected elements: a wide bright outline, the vertices and the direction arrow. */
export function selectedStyle(feature) {
  const element = feature.get("element");
  const color = CLASS_COLORS[element.class] || "#ffffff";
  const styles = [
    new Style({ stroke: new Stroke({ color: "rgba(255, 255, 255, 0.9)", width: 7 }) }),
    new Style({
      stroke: new Stroke({ color, width: 3.5 }),
      fill: element.class === "ped_crossing" ? new Fill({ color: rgba(color, 0.25) }) : undefined,
    }),
    vertexStyle,
  ];
  const arrow = arrowStyle(feature, color);
  if (arrow) styles.push(arrow);
  return styles;
}

/** Style of a conflict draft: the user's own geometry kept beside the server's. */
export const draftStyle = [
  new Style({ stroke: new Stroke({ color: "rgba(249, 115, 22, 0.95)", width: 3, lineDash: [8, 6] }) }),
];

const findingStyles = {
  lint: new Style({
    image: new RegularShape({
      points: 3,
      radius: 9,
      fill: new Fill({ color: "#f59e0b" }),
      stroke: new Stroke({ color: "#1f2937", width: 1.5 }),
    }),
  }),
  issue: new Style({
    image: new Circle({ radius: 8, fill: new Fill({ color: "#6366f1" }), stroke: new Stroke({ color: "#fff", width: 2 }) }),
  }),
  active: new Style({
    image: new Circle({ radius: 14, stroke: new Stroke({ color: "#fde047", width: 3 }) }),
  }),
};

/** Style of lint findings (amber triangles) and review issues (indigo pins); the current one ringed. */
export function findingStyle(feature) {
  const base = findingStyles[feature.get("kind")];
  return feature.get("active") ? [findingStyles.active, base] : [base];
}

/** Style of the leased region's outline: a dashed light frame, no fill, so the rasters stay readable. */
export const regionStyle = [
  new Style({ stroke: new Stroke({ color: "rgba(15, 23, 42, 0.8)", width: 5 }) }),
  new Style({ stroke: new Stroke({ color: "#fde047", width: 2, lineDash: [12, 8] }) }),
];
