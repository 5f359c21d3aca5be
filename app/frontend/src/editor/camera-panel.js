// The camera panel beside the map: the key-frame images that see the selected element (or a map point) best,
// the element projected into each through the refined poses, its neighbours faint, the lane masks on demand,
// stepping along the element through every image that sees it, an enlarged view, and the element's live
// projection while a vertex is dragged. A site without images or poses shows the server's notice instead.
import { h, replaceChildren } from "../dom.js";
import { pointsOf } from "./elements.js";
import { liftPolyline, projectPolyline, toCamera, toPixel, NEAR_M } from "./camera-projection.js";
import { CameraCache, CameraView } from "./camera-view.js";
import { describeFigures } from "./reprojection.js";

const COUNT_KEY = "cama.cameraViews";
const DEFAULT_COUNT = 4;

export class CameraPanel {
  /**
   * @param {{api: import("../api.js").Api, siteId: number, store: import("./elements.js").ElementStore,
   *   tools: import("./tools.js").Tools, sync: import("./sync.js").Sync,
   *   figures: import("./reprojection.js").ReprojectionFigures, onToggle: (open: boolean) => void}} context
   */
  constructor(context) {
    Object.assign(this, context);
    this.base = `/api/sites/${context.siteId}`;
    this.cache = new CameraCache(context.api, this.base);
    this.open = false;
    this.count = Math.min(6, Math.max(2, Number(localStorage.getItem(COUNT_KEY)) || DEFAULT_COUNT));
    this.maskOn = false;
    /** @type {{kind: "element", id: number, version: number} | {kind: "point", x: number, y: number} | null} */
    this.subject = null;
    /** @type {CameraView[]} */
    this.views = [];
    this.all = null; // every candidate along the subject (all=1), fetched on the first step
    this.start = -1; // index into `all` of the first shown view once stepping
    this.lifted = [];
    this.ticket = 0;
    this.liveFrames = 0;
    this.shownAt = null; // performance.now() when the views of the current subject were asked for (bench)
    this.liveDrawMs = []; // how long each live redraw of every view took (the last 240)
    this.enlarged = null;
    this.watched = null;
    this.frame = 0;
    this.onGeometry = () => this.scheduleLive();
    this.build();
    context.tools.addEventListener("selection", () => this.open && this.follow());
    context.sync.addEventListener("changed", () => this.open && this.saved());
  }

  build() {
    this.countSelect = h(
      "select#camera-count",
      { "aria-label": "Number of camera views", title: "Number of camera views", onchange: (e) => this.setCount(Number(e.target.value)) },
      ...[2, 3, 4, 5, 6].map((n) => h("option", { value: n, selected: n === this.count }, `${n} views`)),
    );
    this.maskBox = h("input#camera-mask", { type: "checkbox", "aria-label": "Lane mask overlay (⇧M)", onchange: (e) => this.setMask(e.target.checked) });
    const step = (delta, icon, title) => h("button.small", { onclick: () => this.step(delta), title, "aria-label": title }, icon);
    this.figuresLine = h("div.camera-figures.muted.small#camera-figures", { "aria-live": "polite" });
    this.status = h("div.camera-status#camera-status", { role: "status" });
    this.grid = h("div.camera-grid#camera-grid");
    this.element = h(
      "aside.camera-panel#camera-panel",
      { "aria-label": "Camera views", hidden: true },
      h(
        "div.camera-head",
        {},
        h("h3", {}, "Cameras"),
        h("button.small.ghost", { onclick: () => this.toggle(), title: "Close the camera panel (⇧C)", "aria-label": "Close the camera panel" }, "✕"),
      ),
      h(
        "div.row.camera-controls",
        {},
        this.countSelect,
        h("label.inline.small", { title: "Lane mask overlay (⇧M)" }, this.maskBox, "lane masks"),
        step(-1, "‹", "Previous images along the element ({)"),
        step(1, "›", "Next images along the element (})"),
      ),
      this.figuresLine,
      this.status,
      this.grid,
    );
  }

  /** Open or close the panel (`follow`: show the selection's views on opening). */
  toggle(follow = true) {
    this.open = !this.open;
    this.element.hidden = !this.open;
    this.onToggle(this.open);
    this.element.dispatchEvent(new Event("camera-toggle"));
    if (!this.open) {
      this.ticket++; // answers still on their way are dropped
      this.closeEnlarged();
      this.watch(null);
      this.subject = null; // reopening shows the selection afresh (it may have changed meanwhile)
      return;
    }
    if (follow) this.follow();
  }

  /** Show the views of the current selection (the first selected element), or the site's notice. */
  async follow() {
    const cameras = await this.figures.cameras();
    if (!this.open) return;
    if (!cameras.available) return this.showNotice(cameras);
    const feature = this.tools.selected()[0];
    const element = feature ? this.store.get(/** @type {number} */ (feature.getId())) : null;
    if (!element) {
      this.watch(null);
      this.subject = null;
      this.clear("Select an element, or press ⇧V over the map for the images of the point under the cursor.");
      return;
    }
    if (this.subject && this.subject.kind === "element" && this.subject.id === element.id) return;
    this.watch(feature);
    this.show({ kind: "element", id: element.id, version: element.version });
  }

  /**
   * The images of the map point (site metres) under the cursor (the panel opens if it is closed).
   * @param {number[]|null} xy
   */
  pointViews(xy) {
    if (!xy) return;
    if (!this.open) this.toggle(false);
    this.watch(null);
    this.show({ kind: "point", x: xy[0], y: xy[1] });
  }

  /** A site without camera images or poses: the server's notice, nothing else. */
  showNotice(cameras) {
    this.subject = null;
    this.clear(cameras.notice || "This site has no camera images.");
    this.status.dataset.notice = "true";
  }

  clear(message) {
    this.ticket++;
    this.views = [];
    replaceChildren(this.grid);
    replaceChildren(this.figuresLine);
    this.status.textContent = message;
    delete this.status.dataset.notice;
  }

  /** Query string naming the subject for /views. */
  subjectQuery() {
    const s = /** @type {any} */ (this.subject);
    return s.kind === "element" ? { element_id: s.id } : { x: s.x.toFixed(3), y: s.y.toFixed(3) };
  }

  /** Fetch and show the best views of a subject (or the notice of a site without cameras). */
  async show(subject) {
    this.subject = subject;
    this.all = null;
    this.start = -1;
    this.lifted = [];
    const ticket = ++this.ticket;
    this.shownAt = performance.now();
    this.status.textContent = "Loading camera views…";
    try {
      const cameras = await this.figures.cameras();
      if (ticket !== this.ticket) return;
      if (!cameras.available) return this.showNotice(cameras);
      this.showFigures();
      const answer = await this.api.get(`${this.base}/views`, { ...this.subjectQuery(), n: this.count });
      if (ticket !== this.ticket) return;
      this.render(answer.views, answer.notice);
    } catch (error) {
      if (ticket === this.ticket) this.clear(`Camera views unavailable: ${error.message}`);
    }
  }

  /** The element's reprojection figures above the images. */
  async showFigures() {
    const s = this.subject;
    replaceChildren(this.figuresLine);
    if (!s || s.kind !== "element") return;
    const element = this.store.get(s.id);
    if (!element) return;
    this.figuresLine.appendChild(this.figures.line(element));
  }

  /** Replace the shown views: canvases first, then images, cameras and projections as they arrive. */
  render(descriptors, notice) {
    this.closeEnlarged();
    const ticket = this.ticket;
    const cssWidth = this.grid.clientWidth || 400;
    this.views = descriptors.map((view) => new CameraView({ cache: this.cache, view, cssWidth, onClick: (v) => this.enlarge(v) }));
    replaceChildren(this.grid, ...this.views.map((v) => v.element));
    const where = this.all && this.start >= 0 ? ` (${this.start + 1}–${this.start + this.views.length} of ${this.all.length} along it)` : "";
    const count = `${this.views.length} images${where}`;
    this.status.textContent = this.views.length ? [count, notice].filter(Boolean).join(" · ") : notice || "No key-frame image sees this.";
    for (const view of this.views) this.fill(view, ticket);
  }

  /** Load one view's image and camera, then its projection (element) or marker (point). */
  async fill(view, ticket) {
    try {
      await view.load();
      if (ticket !== this.ticket) return;
      if (this.maskOn) view.setMask(true);
      const s = /** @type {any} */ (this.subject);
      if (s.kind === "element") await this.project(view, s);
      else if (s.z !== undefined) view.setMarker(this.pixelOf(view, [s.x, s.y, s.z]));
      else this.markPoint(s, ticket);
    } catch (error) {
      view.element.dataset.loaded = "error";
      view.element.title = `Camera view unavailable: ${error.message}`;
    }
  }

  /** The server's projection of the subject element into a view. */
  async project(view, subject) {
    const ticket = this.ticket;
    const path = `${this.base}/elements/${subject.id}/projection`;
    const projection = await this.api.get(path, { image: view.view.token, neighbours: 1 });
    if (ticket !== this.ticket) return;
    if (projection.points_3d && projection.points_3d.length) this.lifted = projection.points_3d;
    view.live = null; // the server's projection of the saved version replaces the live one
    view.setProjection(projection);
    view.element.dataset.version = String(subject.version);
    view.element.dataset.projected = "server";
  }

  /** A point subject: its height from the elevation raster, then a marker in every loaded view. */
  async markPoint(subject, ticket) {
    if (subject.zPending) return;
    subject.zPending = true;
    const answer = await this.api.get(`${this.base}/elevation`, { x: subject.x, y: subject.y }).catch(() => null);
    if (ticket !== this.ticket || !answer || answer.elevation_m === null) return;
    subject.z = answer.elevation_m;
    for (const view of this.views) if (view.camera) view.setMarker(this.pixelOf(view, [subject.x, subject.y, subject.z]));
  }

  /** Full-resolution pixel of a site point in a view, or null behind the camera. */
  pixelOf(view, p) {
    const c = toCamera(view.camera.cam_from_site, p);
    return c[2] >= NEAR_M ? toPixel(view.camera.K, c) : null;
  }

  setCount(n) {
    this.count = n;
    localStorage.setItem(COUNT_KEY, String(n));
    if (this.subject && this.all) this.step(0);
    else if (this.subject) this.show(this.subject);
  }

  toggleMask() {
    this.maskBox.checked = !this.maskBox.checked;
    this.setMask(this.maskBox.checked);
  }

  setMask(on) {
    this.maskOn = on;
    for (const view of [...this.views, ...(this.enlarged ? [this.enlarged] : [])]) view.setMask(on);
  }

  /**
   * Step along the subject through every image that sees it (station order): the shown window moves by
   * `delta` images (an enlarged image steps alone).
   * @param {number} delta
   */
  async step(delta) {
    if (!this.open || !this.subject || !this.views.length) return;
    const ticket = this.ticket;
    if (!this.all) {
      const answer = await this.api.get(`${this.base}/views`, { ...this.subjectQuery(), all: 1 }).catch(() => null);
      if (ticket !== this.ticket || !answer) return;
      this.all = answer.views;
    }
    const all = /** @type {any[]} */ (this.all);
    const current = this.enlarged ? this.enlarged.view.token : this.views[0].view.token;
    const at = Math.max(0, all.findIndex((v) => v.token === current));
    if (this.enlarged) {
      const next = all[Math.min(all.length - 1, Math.max(0, at + delta))];
      if (next && next.token !== current) this.enlarge(new CameraView({ cache: this.cache, view: next, cssWidth: 960 }));
      return;
    }
    this.start = Math.min(Math.max(0, all.length - this.count), Math.max(0, at + delta));
    this.render(all.slice(this.start, this.start + this.count));
  }

  /** Show one view large over the page (click or Esc closes it). */
  enlarge(small) {
    this.closeEnlarged();
    const view = new CameraView({ cache: this.cache, view: small.view, cssWidth: Math.min(1600, window.innerWidth * 0.8) });
    this.enlarged = view;
    this.overlay = h(
      "div.overlay.camera-enlarged#camera-enlarged",
      { role: "dialog", "aria-label": `Camera image ${small.view.channel}, enlarged`, onclick: () => this.closeEnlarged() },
      h("div.camera-enlarged-card", {}, view.element, h("p.muted.small", {}, "{ } step along the element · click or Esc closes")),
    );
    document.body.appendChild(this.overlay);
    this.fill(view, this.ticket);
  }

  /** Close the enlarged view; true when one was open (Esc's first job). */
  closeEnlarged() {
    if (!this.overlay) return false;
    this.overlay.remove();
    this.overlay = null;
    this.enlarged = null;
    return true;
  }

  /** Follow this feature's geometry (a vertex drag), or none. */
  watch(feature) {
    if (this.watched) this.watched.un("change", this.onGeometry);
    this.watched = feature;
    if (feature) feature.on("change", this.onGeometry);
  }

  /** Redraw the live projection on the next animation frame (at most once a frame). */
  scheduleLive() {
    if (this.frame || !this.watched || !this.lifted.length) return;
    this.frame = requestAnimationFrame(() => {
      this.frame = 0;
      if (!this.watched) return;
      const started = performance.now();
      const points3d = liftPolyline(pointsOf(this.watched), this.lifted);
      for (const view of [...this.views, ...(this.enlarged ? [this.enlarged] : [])]) {
        if (view.camera) {
          view.setLive(projectPolyline(view.camera, points3d));
          view.element.dataset.projected = "live";
        }
      }
      this.liveFrames++;
      this.liveDrawMs.push(performance.now() - started);
      if (this.liveDrawMs.length > 240) this.liveDrawMs.shift();
    });
  }

  /** After a save (or undo/redo): a new version of the subject element gets the server's projection again. */
  saved() {
    const s = this.subject;
    if (!s || s.kind !== "element") return;
    const element = this.store.get(s.id);
    if (!element || element.version === s.version) return;
    if (element.deleted) return this.clear("The element was deleted.");
    s.version = element.version;
    this.showFigures();
    for (const view of this.views) if (view.camera) this.project(view, s).catch(() => undefined);
  }

  /** What the panel shows, for the browser tests: per view its token, canvas scale and drawn pieces. */
  describe() {
    return {
      open: this.open,
      status: this.status.textContent,
      liveFrames: this.liveFrames,
      liveDrawMs: this.liveDrawMs.slice(),
      shownAt: this.shownAt,
      views: this.views.map((v) => ({
        token: v.view.token,
        width: v.canvas.width,
        height: v.canvas.height,
        scale: v.scale,
        loaded: v.element.dataset.loaded || "",
        loadedAt: v.loadedAt,
        projected: v.element.dataset.projected || "",
        pieces: (v.live || v.pieces).map((piece) => piece.map(([u, w]) => [u * v.scale, w * v.scale])),
      })),
    };
  }
}
