// The top bar's "3D review" link to the viser review (`cama view`, started beside the editor by `cama demo`).
// The backend says where the review is (GET /api/frontend/config); with an element selected, the link opens the
// review focused on it: viser connects its websocket to the URL of its `?websocket=` parameter, and the review
// reads `element` from that URL's query (app/viewer/focus.py).
import { h } from "./dom.js";

/**
 * The review's absolute http(s) URL: a configured `:<port>` means that port on the host the editor was reached by.
 * @param {string} configured
 * @param {Location} location
 */
export function reviewBase(configured, location) {
  return configured.startsWith(":") ? `${location.protocol}//${location.hostname}${configured}/` : configured;
}

/**
 * The link: the review itself, or the review focused on one element.
 * @param {string} base absolute http(s) URL of the review
 * @param {number|null} elementId
 */
export function reviewHref(base, elementId) {
  if (elementId === null) return base;
  const socket = `${base.replace(/^http/, "ws")}?element=${elementId}`;
  return `${base}?websocket=${encodeURIComponent(socket)}`;
}

export class ReviewLink {
  constructor() {
    /** @type {string|null} absolute review URL; null: no review is served, the link stays hidden */
    this.base = null;
    /** @type {number|null} the one site the review shows; null: any */
    this.siteId = null;
    this.elementId = null;
    this.element = h("a.review-link#review-link", { target: "_blank", rel: "noopener", title: "Open the 3D review (viser) in a new tab" }, "3D review");
  }

  /**
   * Ask the backend where the review is; any failure leaves the link hidden (the editor works without it).
   * @param {import("./api.js").Api} api
   */
  async configure(api) {
    try {
      const config = await api.get("/api/frontend/config");
      this.base = config.review_url ? reviewBase(config.review_url, window.location) : null;
      this.siteId = config.review_site_id;
    } catch {
      this.base = null;
    }
  }

  /**
   * The link for a site's views, without an element yet; null when there is no review of that site.
   * @param {number} siteId
   */
  forSite(siteId) {
    this.elementId = null;
    if (!this.base || (this.siteId !== null && this.siteId !== siteId)) return null;
    this.element.href = reviewHref(this.base, null);
    return this.element;
  }

  /**
   * Carry the editor's selection: one selected element focuses the review on it.
   * @param {number[]} ids
   */
  select(ids) {
    if (!this.base) return;
    this.elementId = ids.length === 1 ? ids[0] : null;
    this.element.href = reviewHref(this.base, this.elementId);
    this.element.title = this.elementId === null ? "Open the 3D review (viser) in a new tab" : `Open the 3D review on element #${this.elementId}`;
  }
}
