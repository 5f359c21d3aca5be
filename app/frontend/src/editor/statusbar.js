// The status bar: cursor position and elevation (asked of the backend, throttled), scale, mode, selection,
// element count and the autosave state.
import { h } from "../dom.js";

const ELEVATION_DELAY_MS = 120;
const SAVE_TEXT = { saving: "Saving…", saved: "All changes saved", conflict: "Conflict: see the banner", error: "Last save failed" };

export class StatusBar {
  /**
   * @param {import("../api.js").Api} api
   * @param {number} siteId
   */
  constructor(api, siteId) {
    this.api = api;
    this.siteId = siteId;
    this.timer = 0;
    this.asked = 0;
    this.cursor = h("span.status-item#cursor-xy", {}, "x —  y —");
    this.elevation = h("span.status-item#cursor-elevation", {}, "z —");
    this.scale = h("span.status-item#scale");
    this.mode = h("span.status-item#mode");
    this.selection = h("span.status-item#selection-count");
    this.count = h("span.status-item#element-count");
    this.save = h("span.status-item.save#save-state", {}, SAVE_TEXT.saved);
    this.element = h("footer.statusbar", {}, this.cursor, this.elevation, this.scale, h("span.spacer"), this.mode, this.selection, this.count, this.save);
  }

  /** Show the cursor position now and its elevation once the pointer rests. */
  pointer(coordinate) {
    const [x, y] = coordinate;
    this.cursor.textContent = `x ${x.toFixed(2)} m  y ${y.toFixed(2)} m`;
    clearTimeout(this.timer);
    this.timer = setTimeout(() => this.askElevation(x, y), ELEVATION_DELAY_MS);
  }

  async askElevation(x, y) {
    const ticket = ++this.asked;
    try {
      const answer = await this.api.get(`/api/sites/${this.siteId}/elevation`, { x, y });
      if (ticket !== this.asked) return;
      this.elevation.textContent = answer.elevation_m === null ? "z unobserved" : `z ${answer.elevation_m.toFixed(2)} m`;
    } catch {
      if (ticket === this.asked) this.elevation.textContent = "z n/a";
    }
  }

  setScale(resolution) {
    this.scale.textContent = `${resolution < 1 ? (resolution * 100).toFixed(1) + " cm" : resolution.toFixed(2) + " m"}/px`;
  }

  setMode(text) {
    this.mode.textContent = text;
  }

  setSelection(n) {
    this.selection.textContent = n ? `${n} selected` : "";
  }

  setCount(n) {
    this.count.textContent = `${n} elements`;
  }

  setSave(state) {
    this.save.textContent = SAVE_TEXT[state];
    this.save.dataset.state = state;
  }

  destroy() {
    clearTimeout(this.timer);
  }
}
