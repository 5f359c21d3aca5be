// One camera view of the panel: a canvas with the key-frame image (fetched at the canvas's width), the image's
// lane-instance mask as an optional overlay, the neighbouring elements faint and the selected element bright.
// The element is drawn from the server's projection, or from a live client-side one while it is dragged.
import { h } from "../dom.js";
import { CLASS_COLORS } from "./styles.js";

/** Widths the server scales images to (GET /images/{token}?width=W). */
export const IMAGE_WIDTHS = [240, 320, 480, 640, 960];
/** The selected element's colour in the images: a saturated yellow that road scenes rarely contain. */
export const ELEMENT_COLOR = "rgb(255, 230, 0)";
const BITMAP_CACHE_SIZE = 48;

/**
 * The image width to ask for: the smallest served width covering `cssWidth` device pixels; the full image
 * (null: no width parameter) when no smaller served width covers it.
 * @param {number} cssWidth
 * @param {number} fullWidth
 * @returns {number|null}
 */
export function imageWidthFor(cssWidth, fullWidth) {
  const want = cssWidth * (window.devicePixelRatio || 1);
  const width = IMAGE_WIDTHS.find((w) => w >= want && w < fullWidth);
  return width === undefined ? null : width;
}

/** Images, masks and cameras of one site, shared by every view (stepping back and forth costs nothing). */
export class CameraCache {
  /**
   * @param {import("../api.js").Api} api
   * @param {string} base "/api/sites/N"
   */
  constructor(api, base) {
    this.api = api;
    this.base = base;
    /** @type {Map<string, Promise<any>>} */
    this.cameras = new Map();
    /** @type {Map<string, Promise<ImageBitmap|null>>} */
    this.bitmaps = new Map();
  }

  /** The camera (K, cam_from_site) of an image. */
  camera(token) {
    if (!this.cameras.has(token)) {
      const pending = this.api.get(`${this.base}/images/${encodeURIComponent(token)}/camera`);
      pending.catch(() => this.cameras.delete(token));
      this.cameras.set(token, pending);
    }
    return /** @type {Promise<any>} */ (this.cameras.get(token));
  }

  /**
   * A decoded image or lane mask (null when the server has none: 404), least recently used dropped first.
   * @param {"image"|"mask"} kind
   * @param {string} token
   * @param {number|null} width null: full size
   */
  bitmap(kind, token, width) {
    const key = `${kind}|${token}|${width}`;
    let pending = this.bitmaps.get(key);
    if (pending) this.bitmaps.delete(key);
    else {
      const path = `${this.base}/images/${encodeURIComponent(token)}${kind === "mask" ? "/lane-mask" : ""}${width ? `?width=${width}` : ""}`;
      pending = this.api.imageBlob(path).then((blob) => (blob ? createImageBitmap(blob) : null));
      pending.catch(() => this.bitmaps.delete(key));
    }
    this.bitmaps.set(key, pending);
    while (this.bitmaps.size > BITMAP_CACHE_SIZE) this.bitmaps.delete(this.bitmaps.keys().next().value);
    return pending;
  }
}

/**
 * Stroke pieces (full-resolution pixels) scaled onto the canvas.
 * @param {CanvasRenderingContext2D} ctx
 * @param {number[][][]} pieces
 * @param {number} scale
 */
function strokePieces(ctx, pieces, scale) {
  ctx.beginPath();
  for (const piece of pieces) {
    piece.forEach(([u, v], i) => (i ? ctx.lineTo(u * scale, v * scale) : ctx.moveTo(u * scale, v * scale)));
  }
  ctx.stroke();
}

export class CameraView {
  /**
   * @param {{cache: CameraCache, view: any, cssWidth: number, onClick?: (view: CameraView) => void}} options
   *   view: one entry of GET /views
   */
  constructor({ cache, view, cssWidth, onClick }) {
    this.cache = cache;
    this.view = view;
    this.requestWidth = imageWidthFor(cssWidth, view.width);
    this.width = this.requestWidth || view.width;
    this.canvas = h("canvas.camera-canvas", { width: this.width, height: Math.round((view.height * this.width) / view.width) });
    const label = `${view.channel} ${view.timestamp_us ? new Date(view.timestamp_us / 1000).toISOString().slice(11, 22) : ""}`;
    const caption = h(
      "figcaption.camera-caption",
      {},
      h("span", {}, view.channel),
      h("span.muted", {}, [view.distance_m, view.obliqueness_deg].every((x) => typeof x === "number") ? `${view.distance_m.toFixed(1)} m · ${view.obliqueness_deg.toFixed(0)}°` : ""),
    );
    this.element = h(
      "figure.camera-view",
      { tabindex: 0, role: "button", "aria-label": `Camera image ${label.trim()}, click to enlarge`, dataset: { token: view.token }, title: "Click to enlarge" },
      this.canvas,
      caption,
    );
    if (onClick) {
      this.element.addEventListener("click", () => onClick(this));
      this.element.addEventListener("keydown", (event) => event.key === "Enter" && onClick(this));
    }
    /** @type {ImageBitmap|null} */
    this.image = null;
    /** @type {ImageBitmap|null} */
    this.mask = null;
    this.maskState = "off"; // off | loading | shown | none
    this.camera = null;
    this.pieces = [];
    this.neighbours = [];
    this.live = null;
    this.marker = null;
    /** @type {number|null} performance.now() when the image was first drawn (for the bench) */
    this.loadedAt = null;
  }

  /** Fetch the image and camera; resolves once the first frame is drawn (rejects with the API's error). */
  async load() {
    const [image, camera] = await Promise.all([this.cache.bitmap("image", this.view.token, this.requestWidth), this.cache.camera(this.view.token)]);
    this.image = image;
    this.camera = camera;
    if (image) this.canvas.height = Math.round((image.height * this.width) / image.width);
    this.draw();
    this.loadedAt = performance.now();
    this.element.dataset.loaded = image ? "image" : "missing";
  }

  /** Canvas pixels per full-resolution image pixel. */
  get scale() {
    return this.width / this.view.width;
  }

  /** The server's projection: the element's pieces and its neighbours (full-resolution pixels). */
  setProjection(projection) {
    this.pieces = projection ? projection.pieces : [];
    this.neighbours = projection ? projection.neighbours || [] : [];
    this.draw();
  }

  /** Pieces computed in the browser while the element is dragged (null: back to the server's). */
  setLive(pieces) {
    this.live = pieces;
    this.draw();
  }

  /** A cross at a full-resolution pixel (the map point of "views of a point"), or null. */
  setMarker(pixel) {
    this.marker = pixel;
    this.element.dataset.marker = pixel ? "shown" : "none";
    this.draw();
  }

  /** Show or hide the lane-mask overlay (fetched the first time). */
  async setMask(on) {
    if (!on) {
      this.maskState = "off";
      this.draw();
      return;
    }
    this.maskState = "loading";
    const mask = await this.cache.bitmap("mask", this.view.token, this.requestWidth).catch(() => null);
    if (this.maskState !== "loading") return;
    this.mask = mask;
    this.maskState = mask ? "shown" : "none";
    this.element.dataset.mask = this.maskState;
    this.draw();
  }

  /** Redraw the canvas: image, mask, neighbours faint, the element bright, the marker. */
  draw() {
    const ctx = this.canvas.getContext("2d");
    const { width, height } = this.canvas;
    ctx.fillStyle = "#0b1120";
    ctx.fillRect(0, 0, width, height);
    if (this.image) ctx.drawImage(this.image, 0, 0, width, height);
    if (this.maskState === "shown" && this.mask) ctx.drawImage(this.mask, 0, 0, width, height);
    const s = this.scale;
    ctx.lineJoin = "round";
    ctx.lineCap = "round";
    ctx.setLineDash([]);
    for (const n of this.neighbours) {
      ctx.strokeStyle = CLASS_COLORS[n.cls] || "#ffffff";
      ctx.globalAlpha = 0.45;
      ctx.lineWidth = 1.5;
      strokePieces(ctx, n.pieces, s);
    }
    ctx.globalAlpha = 1;
    const pieces = this.live || this.pieces;
    ctx.strokeStyle = "rgba(0, 0, 0, 0.55)";
    ctx.lineWidth = 4.5;
    strokePieces(ctx, pieces, s);
    ctx.strokeStyle = ELEMENT_COLOR;
    ctx.lineWidth = 2;
    strokePieces(ctx, pieces, s);
    if (this.marker) {
      const [u, v] = [this.marker[0] * s, this.marker[1] * s];
      ctx.strokeStyle = ELEMENT_COLOR;
      ctx.lineWidth = 2;
      ctx.beginPath();
      ctx.moveTo(u - 8, v);
      ctx.lineTo(u + 8, v);
      ctx.moveTo(u, v - 8);
      ctx.lineTo(u, v + 8);
      ctx.stroke();
    }
  }
}
