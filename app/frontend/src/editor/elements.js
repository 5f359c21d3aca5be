// The client's copy of a site's elements: server JSON <-> OpenLayers features, kept in one vector source.
import Feature from "ol/Feature.js";
import LineString from "ol/geom/LineString.js";
import Polygon from "ol/geom/Polygon.js";

/**
 * A geometry for an element's points: polygon ring for crosswalks, polyline otherwise.
 * @param {string} cls
 * @param {number[][]} points
 */
export function geometryFor(cls, points) {
  return cls === "ped_crossing" ? new Polygon([points.map((p) => [p[0], p[1]])]) : new LineString(points.map((p) => [p[0], p[1]]));
}

/**
 * The [x, y] points of a feature's geometry (a crosswalk's ring closed, as the API wants).
 * @param {import("ol/Feature.js").default} feature
 * @returns {number[][]}
 */
export function pointsOf(feature) {
  const geometry = feature.getGeometry();
  const coordinates = geometry.getType() === "Polygon" ? geometry.getCoordinates()[0] : geometry.getCoordinates();
  return coordinates.map((c) => [c[0], c[1]]);
}

/** True when two point lists are the same to a millimetre. */
export function samePoints(a, b) {
  return a.length === b.length && a.every((p, i) => Math.abs(p[0] - b[i][0]) < 1e-3 && Math.abs(p[1] - b[i][1]) < 1e-3);
}

export class ElementStore {
  /** @param {import("ol/source/Vector.js").default} source */
  constructor(source) {
    this.source = source;
    /** @type {Map<number, any>} every element seen, deleted ones too (for undo) */
    this.elements = new Map();
  }

  /** Replace everything with a fresh list from the server. */
  load(elements) {
    this.source.clear(true);
    this.elements.clear();
    const features = [];
    for (const element of elements) {
      this.elements.set(element.id, element);
      if (!element.deleted) features.push(this.makeFeature(element));
    }
    this.source.addFeatures(features);
  }

  makeFeature(element) {
    const feature = new Feature({ geometry: geometryFor(element.class, element.points), element });
    feature.setId(element.id);
    return feature;
  }

  /** @param {number} id */
  get(id) {
    return this.elements.get(id);
  }

  /** @param {number} id */
  feature(id) {
    return this.source.getFeatureById(id);
  }

  /**
   * Take the server's version of an element: update, add or remove its feature.
   * @param {any} element
   */
  upsert(element) {
    this.elements.set(element.id, element);
    const feature = this.feature(element.id);
    if (element.deleted) {
      if (feature) this.source.removeFeature(feature);
      return null;
    }
    if (!feature) {
      const created = this.makeFeature(element);
      this.source.addFeature(created);
      return created;
    }
    const current = pointsOf(feature);
    const kind = element.class === "ped_crossing" ? "Polygon" : "LineString";
    if (feature.getGeometry().getType() !== kind || !samePoints(current, element.points)) {
      feature.setGeometry(geometryFor(element.class, element.points));
    }
    feature.set("element", element);
    return feature;
  }
}
