// The layers panel: a toggle and an opacity slider per raster, with the raster's legend (categorical swatches
// or a colour-bar with its range), plus the vector layer toggles.
import { h } from "../dom.js";

const VIRIDIS = ["#440154", "#482878", "#3e4989", "#31688e", "#26828e", "#1f9e89", "#35b779", "#6ece58", "#b5de2b", "#fde725"];

/** A legend element for a pyramid legend (or null for a plain image). */
export function legendView(legend) {
  if (!legend || legend.kind === "image") return null;
  if (legend.kind === "categorical") {
    return h(
      "div.legend.categorical",
      {},
      ...legend.entries.map((entry) =>
        h("span.legend-entry", {}, h("span.swatch", { style: `background: rgba(${entry.rgba.slice(0, 3).join(",")}, ${entry.rgba[3] / 255})` }), entry.name.replaceAll("_", " ")),
      ),
    );
  }
  const unit = legend.unit ? ` ${legend.unit}` : "";
  const fmt = (v) => (v === null || v === undefined ? "?" : Math.abs(v) >= 100 ? v.toFixed(0) : v.toFixed(2));
  return h(
    "div.legend.continuous",
    {},
    h("div.colorbar", { style: `background: linear-gradient(to right, ${VIRIDIS.join(", ")})` }),
    h("div.colorbar-labels", {}, h("span", {}, `${fmt(legend.min)}${unit}`), h("span.muted", {}, legend.scale === "log" ? "log scale" : ""), h("span", {}, `${fmt(legend.max)}${unit}`)),
  );
}

/**
 * @param {import("ol/layer/Tile.js").default[]} rasters
 * @param {{title: string, layer: import("ol/layer/Base.js").default}[]} overlays
 */
export function layersPanel(rasters, overlays) {
  const rows = rasters.map((layer) => {
    const name = layer.get("name");
    const toggle = h("input", {
      type: "checkbox",
      checked: layer.getVisible(),
      dataset: { layer: name },
      onchange: (event) => layer.setVisible(event.target.checked),
    });
    const opacity = h("input.opacity", {
      type: "range",
      min: 0,
      max: 100,
      value: Math.round(layer.getOpacity() * 100),
      title: "Opacity",
      "aria-label": `${layer.get("title")} opacity`,
      oninput: (event) => layer.setOpacity(Number(event.target.value) / 100),
    });
    return h("div.layer-row", { dataset: { layer: name } }, h("label.inline", {}, toggle, layer.get("title")), opacity, legendView(layer.get("legend")));
  });
  const vectorRows = overlays.map(({ title, layer }) =>
    h("label.inline.layer-row", {}, h("input", { type: "checkbox", checked: layer.getVisible(), onchange: (event) => layer.setVisible(event.target.checked) }), title),
  );
  if (!rows.length) rows.push(h("p.muted.small", {}, "This site has no raster layers."));
  return h("div.layers#layers-panel", {}, ...rows, h("div.divider-line"), ...vectorRows);
}
