// The review panel: what is selected (class, confidence, state, version, author, the model that proposed it), the
// review buttons, the annotator queue's "next" item (leased, centred on the map) or next region, the
// class/confidence key, and each selected element's reprojection figures (on a site with cameras).
import { h, replaceChildren, toast } from "../dom.js";
import { RegionWork } from "./region.js";
import { CLASS_COLORS, CLASS_LABELS, HIGH_CONFIDENCE, LOW_CONFIDENCE, confidenceBucket } from "./styles.js";

const NEXT_RESOLUTION_M = 0.06;
const RENEW_EVERY_MS = 4 * 60 * 1000;

export class ReviewPanel {
  /**
   * @param {{api: import("../api.js").Api, siteId: number, view: import("ol/View.js").default,
   *   store: import("./elements.js").ElementStore, tools: import("./tools.js").Tools,
   *   ops: import("./operations.js").Operations, isLead: boolean,
   *   regionSource: import("ol/source/Vector.js").default,
   *   figures?: import("./reprojection.js").ReprojectionFigures}} context
   */
  constructor(context) {
    Object.assign(this, context);
    this.region = new RegionWork(context);
    this.lease = null;
    this.renewTimer = 0;
    this.info = h("div.selection-info#selection-info");
    this.queueInfo = h("div.muted.small#queue-info");
    const button = (label, key, state, cls = "") =>
      h(`button.review${cls}`, { onclick: () => this.ops.review(state), title: `${label} (${key})`, dataset: { state } }, label, h("kbd", {}, key));
    const leadButtons = this.isLead
      ? h("div.review-buttons.lead-buttons", {}, button("Approve", "⇧A", "approved", ".ok"), button("Return", "⇧R", "returned", ".bad"))
      : null;
    this.element = h(
      "div.review-panel",
      {},
      h(
        "div.next-buttons",
        {},
        h("button.primary#next-item", { onclick: () => this.next(), title: "Next item of my queue (N)" }, "Next item ", h("kbd", {}, "N")),
        h("button#next-region", { onclick: () => this.nextRegion(), title: "Next region of my queue: every proposal of one grid cell (⇧N)" }, "Next region ", h("kbd", {}, "⇧N")),
      ),
      this.queueInfo,
      this.region.element,
      this.info,
      h("div.review-buttons", {}, button("Accept", "A", "accepted", ".ok"), button("Fixed", "F", "fixed", ".fix"), button("Reject", "X", "rejected", ".bad")),
      leadButtons,
      this.key(),
    );
    this.update();
  }

  /** Class colours and the confidence dash key. */
  key() {
    const classes = Object.entries(CLASS_LABELS).map(([cls, label], i) =>
      h("span.key-entry", {}, h("span.key-line", { style: `border-color: ${CLASS_COLORS[cls]}` }), `${label} `, h("kbd", {}, String(i + 1))),
    );
    const dashes = [
      ["solid", `≥ ${HIGH_CONFIDENCE} or drawn`],
      ["dashed", `${LOW_CONFIDENCE}–${HIGH_CONFIDENCE}`],
      ["dotted low", `< ${LOW_CONFIDENCE} (halo)`],
    ].map(([style, label]) => h("span.key-entry", {}, h(`span.key-line.${style.replace(" ", ".")}`), label));
    return h("div.key", {}, h("h4", {}, "Classes"), ...classes, h("h4", {}, "Confidence"), ...dashes);
  }

  /** Redraw the selection summary (and the region's list, whose states may have changed). */
  update() {
    this.region.refresh();
    const features = this.tools.selected();
    if (!features.length) {
      replaceChildren(this.info, h("p.muted", {}, "Nothing selected. Click an element, or press N for the next item."));
      return;
    }
    const rows = features.slice(0, 4).map((feature) => {
      const e = this.store.get(/** @type {number} */ (feature.getId()));
      const confidence = e.confidence === null ? "drawn" : e.confidence.toFixed(2);
      return h(
        "div.selected-element",
        { dataset: { id: String(e.id), state: e.state, cls: e.class, version: String(e.version) } },
        h("div.sel-title", {}, h("span.class-dot", { style: `background: ${CLASS_COLORS[e.class]}` }), `${CLASS_LABELS[e.class]} #${e.id}`, h(`span.state.${e.state}`, {}, e.state)),
        h("div.sel-meta", {}, `confidence ${confidence} (${confidenceBucket(e.confidence)}) · ${e.points.length} vertices · v${e.version}`),
        h("div.sel-meta", {}, "last edit by ", h("span.author", {}, e.author || "?")),
        e.proposed_by ? h("div.sel-meta", {}, "proposed by ", h("span.proposed-by", {}, e.proposed_by)) : null,
        this.figures ? this.figures.line(e) : null,
      );
    });
    if (features.length > 4) rows.push(h("p.muted", {}, `and ${features.length - 4} more`));
    replaceChildren(this.info, ...rows);
  }

  /** Give the current work item or region back (on "next" and when leaving the editor). */
  async release() {
    clearInterval(this.renewTimer);
    const lease = this.lease;
    this.lease = null;
    if (lease) await this.api.post(`/api/leases/${lease.id}/release`, {}).catch(() => undefined);
    await this.region.release();
  }

  /** Lease the next region of my queue (the current item or region is released first). */
  async nextRegion() {
    try {
      await this.release();
      const found = await this.region.next();
      this.queueInfo.textContent = found ? "" : "Your queue is empty.";
    } catch (error) {
      toast(`Next region: ${error.message}`, "error");
    }
  }

  /** Keep the lease while the annotator works on the item (the backend's lease lasts 10 minutes). */
  keepLease() {
    clearInterval(this.renewTimer);
    this.renewTimer = setInterval(async () => {
      if (!this.lease) return;
      try {
        this.lease = await this.api.post(`/api/leases/${this.lease.id}/renew`, {});
      } catch (error) {
        clearInterval(this.renewTimer);
        this.queueInfo.textContent = `Lease lost: ${error.message}`;
      }
    }, RENEW_EVERY_MS);
  }

  /** Lease the next item of my queue, centre the map on it and select it (the previous lease is released). */
  async next() {
    try {
      await this.release();
      const lease = await this.api.post(`/api/sites/${this.siteId}/queue/next`, {});
      this.lease = lease;
      if (!lease) {
        this.queueInfo.textContent = "Your queue is empty.";
        toast("Your queue is empty");
        return;
      }
      this.keepLease();
      const feature = this.store.upsert(lease.element);
      this.queueInfo.textContent = `Item #${lease.element.id} leased until ${new Date(lease.expires_at).toLocaleTimeString()}`;
      if (feature) {
        const extent = feature.getGeometry().getExtent();
        this.view.fit(extent, { padding: [120, 120, 120, 120], minResolution: NEXT_RESOLUTION_M, duration: 250 });
        this.tools.setSelection([feature]);
      }
    } catch (error) {
      toast(`Next: ${error.message}`, "error");
    }
  }
}
