// Per-annotator and per-class figures from the backend, as a table and a small bar chart (SVG built with DOM
// calls, so names stay text).
import { h, replaceChildren, toast } from "../dom.js";

const SVG = "http://www.w3.org/2000/svg";
const BAR_H = 18;

/** An SVG element with attributes. */
function svg(tag, attrs = {}, text) {
  const node = document.createElementNS(SVG, tag);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, String(v));
  if (text !== undefined) node.textContent = text;
  return node;
}

/**
 * Horizontal bars of items handled per annotator (all classes), with the accepted-unchanged share inside.
 * @param {any[]} rows figures with cls == "all"
 */
export function barChart(rows) {
  const width = 420;
  const labelW = 110;
  const max = Math.max(1, ...rows.map((r) => r.items_handled));
  const chart = svg("svg", { width, height: rows.length * (BAR_H + 8) + 8, role: "img", "aria-label": "Items handled per annotator", class: "chart" });
  rows.forEach((row, i) => {
    const y = 4 + i * (BAR_H + 8);
    const w = ((width - labelW - 50) * row.items_handled) / max;
    const unchanged = w * (row.accepted_unchanged_fraction || 0);
    chart.append(
      svg("text", { x: 0, y: y + BAR_H - 5, class: "chart-label" }, row.author),
      svg("rect", { x: labelW, y, width: Math.max(w, 1), height: BAR_H, rx: 3, class: "bar-total" }),
      svg("rect", { x: labelW, y, width: unchanged, height: BAR_H, rx: 3, class: "bar-unchanged" }),
      svg("text", { x: labelW + w + 6, y: y + BAR_H - 5, class: "chart-value" }, String(row.items_handled)),
    );
  });
  return chart;
}

const fmt = (v, digits = 2) => (v === null || v === undefined ? "—" : Number(v).toFixed(digits));

export class FiguresCard {
  constructor(api, siteId) {
    this.api = api;
    this.siteId = siteId;
    this.body = h("div.figures-body");
    this.element = h("section.card.figures#figures", {}, h("div.card-head", {}, h("h3", {}, "Annotators"), h("button.small", { onclick: () => this.reload() }, "Refresh")), this.body);
  }

  async reload() {
    try {
      const rows = await this.api.get(`/api/sites/${this.siteId}/figures`);
      if (!rows.length) {
        replaceChildren(this.body, h("p.muted", {}, "No reviews yet."));
        return;
      }
      const all = rows.filter((r) => r.class === "all");
      const table = h(
        "table.figures-table",
        {},
        h("thead", {}, h("tr", {}, ...["Annotator", "Class", "Items", "Items/h", "Unchanged", "Fixes", "Fix shift (m)"].map((t) => h("th", {}, t)))),
        h(
          "tbody",
          {},
          ...rows.map((r) =>
            h(
              `tr${r.class === "all" ? ".total" : ""}`,
              {},
              h("td.author", {}, r.author),
              h("td", {}, r.class),
              h("td", {}, String(r.items_handled)),
              h("td", {}, fmt(r.items_per_hour, 1)),
              h("td", {}, r.accepted_unchanged_fraction === null ? "—" : `${Math.round(r.accepted_unchanged_fraction * 100)}%`),
              h("td", {}, String(r.fixes)),
              h("td", {}, fmt(r.mean_fix_displacement_m)),
            ),
          ),
        ),
      );
      const legend = h("div.chart-legend.small", {}, h("span.sw.total"), "items handled ", h("span.sw.unchanged"), "accepted unchanged");
      replaceChildren(this.body, barChart(all), legend, table);
    } catch (error) {
      toast(`Figures: ${error.message}`, "error");
    }
  }
}
