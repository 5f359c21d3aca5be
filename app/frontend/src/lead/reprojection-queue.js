// The lead's "worst reprojection" queue, beside the confidence queue: elements sorted by how badly they agree
// with the cameras (unmatched first, then by SRE at 960x540), with the share of images where they matched a
// lane instance. The backend computes missing figures within a time budget and says how many are still
// pending; the card asks again while some are. A click opens the element in the editor.
import { h, replaceChildren, toast } from "../dom.js";
import { CLASS_COLORS, CLASS_LABELS } from "../editor/styles.js";

const LIMIT = 50;
const RETRY_MS = 4000;
const MAX_RETRIES = 8;

/** A figure or a dash. */
function figure(value, format) {
  return value === null || value === undefined ? h("span.muted", {}, "—") : format(value);
}

export class ReprojectionQueue {
  /**
   * @param {import("../api.js").Api} api
   * @param {number} siteId
   */
  constructor(api, siteId) {
    this.api = api;
    this.siteId = siteId;
    this.timer = 0;
    this.retries = 0;
    this.body = h("tbody");
    this.summary = h("div.muted.small#reprojection-summary", { role: "status" });
    this.element = h(
      "section.card.queue#reprojection-queue",
      {},
      h(
        "div.card-head",
        {},
        h("h3", {}, "Worst reprojection"),
        h("button.small", { onclick: () => this.reload(), title: "Ask for the figures again", "aria-label": "Refresh the reprojection queue" }, "Refresh"),
      ),
      h("p.muted.small", {}, "SRE against the images' lane masks at 960×540; unmatched elements first."),
      h("table.queue-table#reprojection-table", {}, h("thead", {}, h("tr", {}, ...["#", "Class", "SRE px", "Matched", "Images", "State"].map((t) => h("th", {}, t)))), this.body),
      this.summary,
    );
  }

  /** The first load: a site without camera images or poses shows the server's notice and asks nothing more. */
  async start() {
    const cameras = await this.api.get(`/api/sites/${this.siteId}/cameras`).catch((error) => ({ available: false, notice: error.message }));
    if (cameras.available) return this.reload();
    replaceChildren(this.body, h("tr", {}, h("td.muted", { colSpan: 6 }, cameras.notice || "This site has no camera images.")));
  }

  /** Fetch the queue; while the backend reports pending figures, fetch it again a few times. */
  async reload(retry = false) {
    clearTimeout(this.timer);
    if (!retry) this.retries = 0;
    try {
      const page = await this.api.get(`/api/sites/${this.siteId}/queues/reprojection`, { limit: LIMIT });
      const items = page.items || [];
      replaceChildren(this.body, ...items.map((e) => this.row(e)));
      if (!items.length) this.body.appendChild(h("tr", {}, h("td.muted", { colSpan: 6 }, page.notice || "No element has reprojection figures yet.")));
      const pending = page.pending || 0;
      const counts = `${page.total ?? items.length} ranked${page.unseen ? `, ${page.unseen} seen by no image` : ""}`;
      this.summary.textContent = [counts, pending ? `${pending} still being computed…` : "", page.notice || ""].filter(Boolean).join(" · ");
      if (pending && this.retries < MAX_RETRIES) {
        this.retries += 1;
        this.timer = setTimeout(() => this.reload(true), RETRY_MS);
      }
    } catch (error) {
      replaceChildren(this.body, h("tr", {}, h("td.muted", { colSpan: 6 }, `Unavailable: ${error.message}`)));
      if (!retry) toast(`Reprojection queue: ${error.message}`, "error");
    }
  }

  /** One row; a click opens the element in the editor. */
  row(e) {
    const id = e.id ?? e.element_id;
    const cls = e.class ?? e.cls;
    return h(
      "tr.queue-row",
      {
        onclick: () => {
          window.location.hash = `#/site/${this.siteId}?element=${id}`;
        },
        dataset: { id: String(id), sre: e.sre_px === null || e.sre_px === undefined ? "" : String(e.sre_px) },
        title: "Open in the editor",
      },
      h("td", {}, String(id)),
      h("td", {}, h("span.class-dot", { style: `background: ${CLASS_COLORS[cls] || "#fff"}` }), CLASS_LABELS[cls] || cls || ""),
      h("td", {}, figure(e.sre_px, (v) => v.toFixed(2))),
      h("td", {}, figure(e.matched_share, (v) => `${Math.round(v * 100)} %`)),
      h("td", {}, figure(e.images, (v) => String(v))),
      h("td", {}, e.state ? h(`span.state.${e.state}`, {}, e.state) : ""),
    );
  }

  destroy() {
    clearTimeout(this.timer);
  }
}
