// An element's reprojection figures (the backend's SRE against the image lane masks at 960x540, and the share
// of the images that see it where it matched a lane instance), fetched once per element version and shown in
// the camera panel and the review panel.
import { h } from "../dom.js";

/**
 * The figures as one line of text.
 * @param {any} f GET /elements/{id}/reprojection
 */
export function describeFigures(f) {
  if (!f.images) return `reprojection: ${f.notice || "no camera image sees it"}`;
  const sre = f.sre_px === null || f.sre_px === undefined ? "SRE — (no match)" : `SRE ${f.sre_px.toFixed(2)} px`;
  const share = f.matched_share === null || f.matched_share === undefined ? "—" : `${Math.round(f.matched_share * 100)} %`;
  return `reprojection: ${sre} · matched in ${share} of ${f.images} images`;
}

export class ReprojectionFigures {
  /**
   * @param {import("../api.js").Api} api
   * @param {number} siteId
   */
  constructor(api, siteId) {
    this.api = api;
    this.base = `/api/sites/${siteId}/elements`;
    this.siteBase = `/api/sites/${siteId}`;
    /** @type {Map<string, Promise<any>>} */
    this.cache = new Map();
    /** @type {Promise<any>|null} */
    this.camerasAnswer = null;
  }

  /** Whether the site has camera images and poses (GET /cameras, asked once; a failure reads as none). */
  cameras() {
    if (!this.camerasAnswer) {
      this.camerasAnswer = this.api.get(`${this.siteBase}/cameras`).catch((error) => ({ available: false, notice: `Camera views unavailable: ${error.message}` }));
    }
    return this.camerasAnswer;
  }

  /**
   * The figures of an element as it is now (a new version is asked for afresh).
   * @param {{id: number, version: number}} element
   */
  get(element) {
    const key = `${element.id}:${element.version}`;
    if (!this.cache.has(key)) {
      const pending = this.api.get(`${this.base}/${element.id}/reprojection`);
      pending.catch(() => this.cache.delete(key));
      this.cache.set(key, pending);
      if (this.cache.size > 500) this.cache.delete(this.cache.keys().next().value);
    }
    return /** @type {Promise<any>} */ (this.cache.get(key));
  }

  /**
   * A line that fills itself in when the figures arrive (data-sre carries the number, for tests and styling);
   * hidden on a site without cameras.
   * @param {{id: number, version: number}} element
   */
  line(element) {
    const node = h("div.sel-meta.reprojection", { dataset: { id: String(element.id), version: String(element.version) } }, "reprojection …");
    this.cameras()
      .then((cameras) => {
        if (cameras.available) return this.get(element);
        node.hidden = true;
        return new Promise(() => undefined);
      })
      .then(
      (f) => {
        node.textContent = describeFigures(f);
        node.dataset.sre = f.sre_px === null || f.sre_px === undefined ? "" : String(f.sre_px);
        node.dataset.matched = f.matched_share === null || f.matched_share === undefined ? "" : String(f.matched_share);
        node.dataset.state = "ready";
      },
      (error) => {
        node.textContent = `reprojection unavailable: ${error.message}`;
        node.dataset.state = "error";
      },
    );
    return node;
  }
}
