// Region work items (POST queue/next-region): a grid cell of the site with one lease per free proposal in it.
// The map zooms to the cell with its outline drawn, the panel lists its elements (done once reviewed) and the
// time left on the leases; they are renewed while the annotator works and released on "next" or on leaving,
// as single work items are. A reviewed element's lease is ended by the backend with the review.
import Feature from "ol/Feature.js";
import { fromExtent } from "ol/geom/Polygon.js";
import { h, replaceChildren, toast } from "../dom.js";
import { CLASS_COLORS, CLASS_LABELS } from "./styles.js";

const RENEW_EVERY_MS = 4 * 60 * 1000;
const OPEN_STATES = new Set(["proposed", "returned"]);

/** "9:05" for a number of seconds (0 when past). */
export function timeLeft(seconds) {
  const s = Math.max(0, Math.floor(seconds));
  return `${Math.floor(s / 60)}:${String(s % 60).padStart(2, "0")}`;
}

export class RegionWork {
  /**
   * @param {{api: import("../api.js").Api, siteId: number, view: import("ol/View.js").default,
   *   store: import("./elements.js").ElementStore, tools: import("./tools.js").Tools,
   *   regionSource: import("ol/source/Vector.js").default}} context
   */
  constructor(context) {
    Object.assign(this, context);
    /** @type {{bbox: number[], leases: any[]}|null} */
    this.region = null;
    this.renewTimer = 0;
    this.clockTimer = 0;
    this.status = h("div.region-status#region-status");
    this.list = h("ol.region-list#region-list");
    const hint = h("p.muted.small", {}, h("kbd", {}, "."), " / ", h("kbd", {}, ","), " next / previous to review");
    this.element = h("div.region-panel#region-panel", { hidden: true }, this.status, this.list, hint);
  }

  /** True while the element still needs a review (not reviewed, not deleted). */
  isOpen(id) {
    const element = this.store.get(id);
    return Boolean(element) && !element.deleted && OPEN_STATES.has(element.state);
  }

  /** Ids of the region's elements still to review, in the region's order. */
  openIds() {
    return this.region ? this.region.leases.map((lease) => lease.element_id).filter((id) => this.isOpen(id)) : [];
  }

  /** Lease the next region, show it and select its first element; the current one is released first. */
  async next() {
    await this.release();
    const region = await this.api.post(`/api/sites/${this.siteId}/queue/next-region`, {});
    if (!region) {
      toast("No region left in your queue");
      return false;
    }
    this.region = region;
    for (const lease of region.leases) this.store.upsert(lease.element);
    const [xmin, ymin, xmax, ymax] = region.bbox;
    this.regionSource.addFeature(new Feature({ geometry: fromExtent([xmin, ymin, xmax, ymax]) }));
    this.view.fit([xmin, ymin, xmax, ymax], { padding: [40, 40, 40, 40], duration: 250 });
    this.keepLeases();
    this.refresh();
    this.step(1);
    return true;
  }

  /** Select the next (or previous) element of the region still to review ("." and ","). */
  step(direction) {
    const open = this.openIds();
    if (!open.length) return;
    const selected = this.tools.selected();
    const at = selected.length === 1 ? open.indexOf(/** @type {number} */ (selected[0].getId())) : -1;
    const index = at === -1 ? (direction > 0 ? 0 : open.length - 1) : (at + direction + open.length) % open.length;
    this.selectElement(open[index]);
  }

  selectElement(id) {
    const feature = this.store.feature(id);
    if (feature) this.tools.setSelection([feature]);
  }

  /** Redraw the list and the lease clock; once every element is reviewed, the region is complete. */
  refresh() {
    this.element.hidden = !this.region;
    if (!this.region) return;
    const rows = this.region.leases.map((lease) => this.row(lease.element_id));
    replaceChildren(this.list, ...rows);
    this.tick();
  }

  row(id) {
    const element = this.store.get(id);
    const done = !this.isOpen(id);
    const state = element.deleted ? "deleted" : element.state;
    return h(
      `li.region-item${done ? ".done" : ""}`,
      { dataset: { id: String(id), state } },
      h(
        "button.ghost.region-pick",
        { onclick: () => this.selectElement(id), disabled: element.deleted },
        h("span.class-dot", { style: `background: ${CLASS_COLORS[element.class]}` }),
        `${CLASS_LABELS[element.class]} #${id}`,
      ),
      h(`span.state.${state}`, {}, state),
    );
  }

  /** The status line: how many are done and the time left on the soonest-expiring open lease. */
  tick() {
    if (!this.region) return;
    const total = this.region.leases.length;
    const open = new Set(this.openIds());
    const [xmin, ymin, xmax, ymax] = this.region.bbox;
    const size = `${(xmax - xmin).toFixed(0)} × ${(ymax - ymin).toFixed(0)} m`;
    if (!open.size) {
      this.status.dataset.state = "complete";
      replaceChildren(this.status, h("strong", {}, `Region complete (${total}/${total})`), " · press ", h("kbd", {}, "⇧N"), " for the next");
      if (this.renewTimer) this.complete();
      return;
    }
    const expires = Math.min(...this.region.leases.filter((l) => open.has(l.element_id)).map((l) => Date.parse(l.expires_at)));
    const seconds = (expires - Date.now()) / 1000;
    this.status.dataset.state = seconds > 0 ? "leased" : "expired";
    const lease = seconds > 0 ? `lease ${timeLeft(seconds)} left` : "lease expired: ask for the next region";
    replaceChildren(this.status, h("strong", {}, `Region ${size}`), ` · ${total - open.size}/${total} done · `, h("span.lease-left#region-lease", {}, lease));
  }

  /** Renew the open leases every few minutes and tick the clock every second. */
  keepLeases() {
    this.stopTimers();
    this.clockTimer = setInterval(() => this.tick(), 1000);
    this.renewTimer = setInterval(() => this.renew(), RENEW_EVERY_MS);
  }

  async renew() {
    if (!this.region) return;
    const open = new Set(this.openIds());
    const renewed = await Promise.all(
      this.region.leases.map((lease) =>
        open.has(lease.element_id) ? this.api.post(`/api/leases/${lease.id}/renew`, {}).catch(() => lease) : lease,
      ),
    );
    if (this.region) this.region.leases = renewed;
    this.tick();
  }

  stopTimers() {
    clearInterval(this.renewTimer);
    clearInterval(this.clockTimer);
    this.renewTimer = 0;
  }

  /** Every element reviewed or deleted: stop renewing and give back the deleted ones' leases (reviews ended the rest). */
  complete() {
    this.stopTimers();
    const deleted = this.region.leases.filter((lease) => this.store.get(lease.element_id).deleted);
    this.releaseLeases(deleted);
    toast("Region complete", "ok");
  }

  /** @param {any[]} leases */
  releaseLeases(leases) {
    return Promise.all(leases.map((lease) => this.api.post(`/api/leases/${lease.id}/release`, {}).catch(() => undefined)));
  }

  /** Give back the leases still held and clear the outline (on "next" and when leaving the editor). */
  async release() {
    const region = this.region;
    const held = region ? region.leases.filter((l) => this.isOpen(l.element_id) || this.store.get(l.element_id).deleted) : [];
    this.stopTimers();
    this.region = null;
    this.regionSource.clear();
    this.refresh();
    await this.releaseLeases(held);
  }
}
