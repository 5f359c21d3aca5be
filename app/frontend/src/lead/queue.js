// The lead's review queue: a table sorted by confidence (lowest first, as the backend orders it), filters by
// class, state and author (or only the pre-accepted QA sample), approve/return per row, and a click opens the
// element in the editor. Pre-accepted elements (entered as accepted by the model's confidence) carry a badge.
import { h, replaceChildren, shortTime, toast } from "../dom.js";
import { CLASS_COLORS, CLASS_LABELS, confidenceBucket } from "../editor/styles.js";

const STATES = ["", "proposed", "accepted", "fixed", "rejected", "approved", "returned"];
const PAGE = 100;

export class QueueTable {
  /**
   * @param {import("../api.js").Api} api
   * @param {number} siteId
   */
  constructor(api, siteId) {
    this.api = api;
    this.siteId = siteId;
    this.offset = 0;
    this.cls = h("select#filter-class", { onchange: () => this.reload(0) }, h("option", { value: "" }, "all classes"), ...Object.entries(CLASS_LABELS).map(([v, l]) => h("option", { value: v }, l)));
    this.state = h("select#filter-state", { onchange: () => this.reload(0) }, ...STATES.map((s) => h("option", { value: s }, s || "all states")));
    this.author = h("input#filter-author", { placeholder: "author", onchange: () => this.reload(0) });
    this.qa = h("input#filter-qa", { type: "checkbox", onchange: () => this.reload(0) });
    this.body = h("tbody");
    this.pager = h("div.pager");
    this.element = h(
      "section.card.queue",
      {},
      h("div.card-head", {}, h("h3", {}, "Confidence queue"), h("div.filters", {}, this.cls, this.state, this.author, h("label.qa-filter", { title: "Pre-accepted elements sampled for QA" }, this.qa, "QA sample"))),
      h("table.queue-table#queue-table", {}, h("thead", {}, h("tr", {}, ...["#", "Class", "Confidence", "State", "Author", "Updated", ""].map((t) => h("th", {}, t)))), this.body),
      this.pager,
    );
  }

  async reload(offset = this.offset) {
    this.offset = offset;
    try {
      const page = await this.api.get(`/api/sites/${this.siteId}/queue/review`, {
        class: this.cls.value,
        state: this.state.value,
        author: this.author.value.trim(),
        qa: this.qa.checked ? "true" : "",
        limit: PAGE,
        offset,
      });
      replaceChildren(this.body, ...page.items.map((e) => this.row(e)));
      if (!page.items.length) this.body.appendChild(h("tr", {}, h("td.muted", { colSpan: 7 }, "Nothing in the queue with these filters.")));
      const last = Math.min(page.offset + page.items.length, page.total);
      replaceChildren(
        this.pager,
        h("span.muted", {}, `${page.total ? page.offset + 1 : 0}–${last} of ${page.total}`),
        h("button.small", { disabled: offset === 0, onclick: () => this.reload(Math.max(0, offset - PAGE)) }, "‹"),
        h("button.small", { disabled: last >= page.total, onclick: () => this.reload(offset + PAGE) }, "›"),
      );
    } catch (error) {
      toast(`Queue: ${error.message}`, "error");
    }
  }

  /** One row; clicking it (outside the buttons) opens the element in the editor. */
  row(e) {
    const open = () => {
      window.location.hash = `#/site/${this.siteId}?element=${e.id}`;
    };
    const confidence = e.confidence === null ? h("span.muted", {}, "drawn") : h("span.conf", {}, h("span.conf-bar", {}, h(`span.conf-fill.${confidenceBucket(e.confidence)}`, { style: `width: ${Math.round(e.confidence * 100)}%` })), e.confidence.toFixed(2));
    const act = (label, state) =>
      h(`button.small.${state}`, {
        onclick: async (event) => {
          event.stopPropagation();
          try {
            await this.api.post(`/api/sites/${this.siteId}/elements/${e.id}/review`, { state, version: e.version });
            toast(`#${e.id} ${state}`, "ok");
            this.reload();
          } catch (error) {
            toast(`#${e.id}: ${error.message}`, "error");
          }
        },
      }, label);
    const canDecide = e.state === "accepted" || e.state === "fixed";
    return h(
      "tr.queue-row",
      { onclick: open, dataset: { id: String(e.id), confidence: e.confidence === null ? "" : String(e.confidence) }, title: "Open in the editor" },
      h("td", {}, String(e.id)),
      h("td", {}, h("span.class-dot", { style: `background: ${CLASS_COLORS[e.class]}` }), CLASS_LABELS[e.class]),
      h("td", {}, confidence),
      h(
        "td",
        {},
        h(`span.state.${e.state}`, {}, e.state),
        e.preaccepted ? h("span.badge.preaccepted", { title: "Entered as accepted: confidence above the calibrated threshold" }, "pre-accepted") : null,
        e.qa_sample ? h("span.badge.qa", { title: "Sampled for the lead's QA" }, "QA") : null,
      ),
      h("td.author", {}, e.author || ""),
      h("td.muted", {}, shortTime(e.updated_at)),
      h("td.actions", {}, canDecide ? act("Approve", "approved") : null, canDecide ? act("Return", "returned") : null),
    );
  }
}
