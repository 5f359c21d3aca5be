// The map: a metric projection in site metres, one tiled image layer per BEV raster (fetched with the token),
// the element layer and overlays. Pan/zoom stays smooth on large sites because only visible tiles load.
import Map from "ol/Map.js";
import View from "ol/View.js";
import Projection from "ol/proj/Projection.js";
import TileLayer from "ol/layer/Tile.js";
import VectorLayer from "ol/layer/Vector.js";
import TileImage from "ol/source/TileImage.js";
import VectorSource from "ol/source/Vector.js";
import TileGrid from "ol/tilegrid/TileGrid.js";
import TileState from "ol/TileState.js";
import { defaults as defaultControls, ScaleLine } from "ol/control.js";
import { defaults as defaultInteractions } from "ol/interaction/defaults.js";
import { elementStyle, findingStyle, regionStyle } from "./styles.js";

export const LAYER_TITLES = {
  photometric: "Photometric",
  semantic: "Semantic",
  elevation: "Elevation",
  observation_count: "Observation count",
};
const DEFAULT_VISIBLE = new Set(["photometric"]);

/**
 * The tile grid of a pyramid in site metres: origin at the raster's top-left corner, level z at
 * resolution * 2^(max_zoom - z), XYZ rows growing downwards (as the backend cuts them).
 * @param {any} pyramid PyramidInfo from /layers
 * @param {number[]} siteOrigin
 */
export function pyramidGrid(pyramid, siteOrigin) {
  const geo = pyramid.georeference;
  const left = geo.origin_xy[0] - geo.resolution / 2 - siteOrigin[0];
  const top = geo.origin_xy[1] + geo.resolution / 2 - siteOrigin[1];
  const resolutions = pyramid.levels.map((level) => geo.resolution * 2 ** (pyramid.max_zoom - level.z));
  const extent = [left, top - geo.height * geo.resolution, left + geo.width * geo.resolution, top];
  return new TileGrid({ origin: [left, top], resolutions, tileSize: pyramid.tile_size, extent });
}

/**
 * A tile image drawn at the top-left of a full tile_size square: the backend cuts the right and bottom edge
 * tiles to the raster, and OpenLayers would stretch them to a full tile.
 * @param {Blob} blob
 * @param {number} size
 */
async function fullTile(blob, size) {
  const bitmap = await createImageBitmap(blob);
  const canvas = document.createElement("canvas");
  canvas.width = size;
  canvas.height = size;
  canvas.getContext("2d").drawImage(bitmap, 0, 0);
  bitmap.close();
  return canvas;
}

/**
 * A tile layer of one raster; tiles come through fetch with the bearer token, 404 tiles are left empty.
 * @param {import("../api.js").Api} api
 * @param {any} layer LayerPublic
 * @param {number[]} siteOrigin
 * @param {Projection} projection
 */
function rasterLayer(api, layer, siteOrigin, projection) {
  const template = layer.tile_url;
  const source = new TileImage({
    projection,
    tileGrid: pyramidGrid(layer.pyramid, siteOrigin),
    interpolate: layer.name !== "semantic",
    transition: 150,
    tileUrlFunction: ([z, x, y]) => template.replace("{z}", String(z)).replace("{x}", String(x)).replace("{y}", String(y)),
    tileLoadFunction: (tile, src) => {
      api
        .imageBlob(src)
        .then((blob) => (blob ? fullTile(blob, layer.pyramid.tile_size) : null))
        .then(
          (canvas) => (canvas ? /** @type {any} */ (tile).setImage(canvas) : tile.setState(TileState.EMPTY)),
          () => tile.setState(TileState.ERROR),
        );
    },
  });
  return new TileLayer({
    source,
    visible: DEFAULT_VISIBLE.has(layer.name),
    opacity: layer.name === "photometric" ? 1 : 0.75,
    properties: { name: layer.name, title: LAYER_TITLES[layer.name] || layer.name, legend: layer.pyramid.legend },
    preload: 1,
  });
}

/**
 * Show the whole site; call once the page layout is final (the map measures its element).
 * @param {{map: Map, view: View, extent: number[]}} m
 */
export function fitSite(m) {
  m.map.updateSize();
  m.view.fit(m.extent, { size: m.map.getSize(), padding: [60, 20, 20, 20] });
}

/**
 * Build the map for a site (call `fitSite` once the layout is final).
 * @param {HTMLElement} target
 * @param {import("../api.js").Api} api
 * @param {any} site SiteDetail
 * @param {any[]} layers LayerPublic list
 */
export function createMap(target, api, site, layers) {
  const e = site.extent;
  const extent = [e.xmin, e.ymin, e.xmax, e.ymax];
  const projection = new Projection({ code: `cama-site-${site.id}`, units: "m", extent, metersPerUnit: 1 });
  const rasters = layers.map((layer) => rasterLayer(api, layer, site.site_origin_xy, projection));
  const elementSource = new VectorSource({ wrapX: false });
  const elementLayer = new VectorLayer({
    source: elementSource,
    style: elementStyle,
    updateWhileInteracting: true,
    properties: { name: "elements" },
  });
  const findingSource = new VectorSource({ wrapX: false });
  const findingLayer = new VectorLayer({ source: findingSource, style: findingStyle, properties: { name: "findings" } });
  const regionSource = new VectorSource({ wrapX: false });
  const regionLayer = new VectorLayer({ source: regionSource, style: regionStyle, properties: { name: "region" } });
  const draftSource = new VectorSource({ wrapX: false });
  const draftLayer = new VectorLayer({ source: draftSource, properties: { name: "drafts" } });
  const span = Math.max(e.xmax - e.xmin, e.ymax - e.ymin, 1);
  const margin = span * 0.25;
  const view = new View({
    projection,
    center: [(e.xmin + e.xmax) / 2, (e.ymin + e.ymax) / 2],
    extent: [e.xmin - margin, e.ymin - margin, e.xmax + margin, e.ymax + margin],
    constrainOnlyCenter: true,
    maxResolution: span / 128,
    minResolution: 0.005,
    smoothResolutionConstraint: true,
  });
  const map = new Map({
    target,
    layers: [...rasters, regionLayer, elementLayer, draftLayer, findingLayer],
    view,
    controls: defaultControls({ rotate: false, attribution: false }).extend([new ScaleLine({ units: "metric" })]),
    interactions: defaultInteractions({ doubleClickZoom: false, pinchRotate: false, altShiftDragRotate: false }),
    keyboardEventTarget: undefined,
  });
  return { map, view, extent, rasters, elementSource, elementLayer, findingSource, draftSource, regionSource };
}
