// Lint findings and pinned review issues: markers on the map, a list in the sidebar, "next/previous" jumps and
// the issue's comment thread (replies; leads pin, resolve and reopen). All user text is rendered as text.
import Feature from "ol/Feature.js";
import Point from "ol/geom/Point.js";
import { h, replaceChildren, shortTime, toast } from "../dom.js";

export const ISSUE_REASONS = ["wrong_class", "wrong_geometry", "wrong_direction", "missing_element", "extra_element", "other"];
const FOCUS_RESOLUTION_M = 0.08;

export class Findings {
  /**
   * @param {{api: import("../api.js").Api, siteId: number, source: import("ol/source/Vector.js").default,
   *   view: import("ol/View.js").default, store: import("./elements.js").ElementStore,
   *   tools: import("./tools.js").Tools, isLead: boolean}} context
   */
  constructor(context) {
    Object.assign(this, context);
    /** @type {any[]} */
    this.items = [];
    this.index = -1;
    this.showResolved = false;
    this.list = h("div.finding-list#finding-list");
    this.thread = h("div.thread#issue-thread");
    this.summary = h("div.muted.small");
    const resolvedToggle = h("input", {
      type: "checkbox",
      onchange: (event) => {
        this.showResolved = event.target.checked;
        this.refresh();
      },
    });
    const actions = h(
      "div.row",
      {},
      h("button.small", { onclick: () => this.step(-1), title: "Previous finding ([)" }, "‹ Prev"),
      h("button.small", { onclick: () => this.step(1), title: "Next finding (])" }, "Next ›"),
      h("button.small", { onclick: () => this.refresh(), title: "Run lint again" }, "Refresh"),
      this.isLead ? h("button.small#new-issue", { onclick: () => this.openNewIssue() }, "+ Issue") : null,
    );
    this.element = h(
      "div.findings",
      {},
      actions,
      h("label.inline.small", {}, resolvedToggle, "show resolved issues"),
      this.summary,
      this.list,
      this.thread,
    );
  }

  /** Fetch lint findings and issues again and redraw markers and list. */
  async refresh() {
    const base = `/api/sites/${this.siteId}`;
    try {
      const [lint, issues] = await Promise.all([
        this.api.get(`${base}/lint`),
        this.api.get(`${base}/issues`, { status: this.showResolved ? undefined : "open", limit: 1000 }),
      ]);
      const lintItems = lint.findings.map((f, i) => ({ kind: "lint", key: `lint-${i}-${f.code}`, xy: f.location_xy, finding: f }));
      const issueItems = issues.map((issue) => ({ kind: "issue", key: `issue-${issue.id}`, xy: this.issueXY(issue), issue }));
      const activeKey = this.items[this.index]?.key;
      this.items = [...issueItems.filter((i) => i.xy), ...lintItems];
      this.index = this.items.findIndex((item) => item.key === activeKey);
      this.render();
    } catch (error) {
      toast(`Findings: ${error.message}`, "error");
    }
  }

  /** Where an issue sits: its point, else its element's middle vertex. */
  issueXY(issue) {
    if (issue.point) return issue.point;
    const element = issue.element_id ? this.store.get(issue.element_id) : null;
    return element ? element.points[Math.floor(element.points.length / 2)] : null;
  }

  render() {
    const features = this.items.map((item, i) => {
      const feature = new Feature({ geometry: new Point(item.xy), kind: item.kind, active: i === this.index });
      feature.setId(item.key);
      return feature;
    });
    this.source.clear(true);
    this.source.addFeatures(features);
    const lintCount = this.items.filter((i) => i.kind === "lint").length;
    this.summary.textContent = `${this.items.length - lintCount} issue(s), ${lintCount} lint finding(s)`;
    replaceChildren(
      this.list,
      ...this.items.map((item, i) => {
        const title = item.kind === "lint" ? item.finding.code : `#${item.issue.id} ${item.issue.reason.replace("_", " ")}`;
        const text = item.kind === "lint" ? item.finding.message : item.issue.comments[0]?.body || "";
        const badge = item.kind === "lint" ? item.finding.severity : item.issue.status;
        return h(
          `button.finding.${item.kind}${i === this.index ? ".active" : ""}`,
          { onclick: () => this.focus(i), dataset: { key: item.key } },
          h("span.finding-title", {}, title, h("span.badge", {}, badge)),
          h("span.finding-text", {}, text),
        );
      }),
    );
    this.renderThread();
  }

  /** Go to the next (+1) or previous (-1) finding. */
  step(delta) {
    if (!this.items.length) {
      toast("No findings");
      return;
    }
    const n = this.items.length;
    this.focus(((this.index < 0 ? (delta > 0 ? -1 : 0) : this.index) + delta + n) % n);
  }

  /** Centre the map on a finding, select the elements involved and show its thread. */
  focus(i) {
    this.index = i;
    const item = this.items[i];
    const resolution = Math.min(this.view.getResolution() || FOCUS_RESOLUTION_M, FOCUS_RESOLUTION_M * 4);
    this.view.animate({ center: item.xy, resolution, duration: 250 });
    const ids = item.kind === "lint" ? item.finding.element_ids : item.issue.element_id ? [item.issue.element_id] : [];
    this.tools.setSelection(ids.map((id) => this.store.feature(id)).filter(Boolean));
    this.render();
    const active = this.list.querySelector(".finding.active");
    if (active) active.scrollIntoView({ block: "nearest" });
  }

  /** The comment thread of the focused issue (or nothing for a lint finding). */
  renderThread() {
    const item = this.items[this.index];
    if (!item || item.kind !== "issue") {
      replaceChildren(this.thread);
      return;
    }
    const issue = item.issue;
    const reply = h("textarea#reply-text", { rows: 2, placeholder: "Reply…", maxLength: 10000 });
    const comments = issue.comments.map((c) =>
      h(
        `div.comment.${c.kind}`,
        {},
        h("div.comment-head", {}, h("strong.comment-user", {}, c.username), h("span.muted", {}, ` ${c.kind} · ${shortTime(c.at)}`)),
        h("div.comment-body", {}, c.body),
      ),
    );
    const leadButtons = this.isLead
      ? [issue.status === "open" ? h("button.small", { onclick: () => this.setStatus(issue, "resolve") }, "Resolve") : h("button.small", { onclick: () => this.setStatus(issue, "reopen") }, "Reopen")]
      : [];
    replaceChildren(
      this.thread,
      h("h4", {}, `Issue #${issue.id} · ${issue.reason.replaceAll("_", " ")} · ${issue.status}`),
      h("div.muted.small", {}, `pinned by `, h("span.issue-author", {}, issue.created_by), issue.element_id ? ` on element #${issue.element_id}` : ""),
      ...comments,
      reply,
      h("div.row", {}, h("button.small.primary#send-reply", { onclick: () => this.reply(issue, reply.value) }, "Reply"), ...leadButtons),
    );
  }

  async reply(issue, body) {
    if (!body.trim()) return;
    try {
      const updated = await this.api.post(`/api/issues/${issue.id}/comments`, { body });
      this.replaceIssue(updated);
    } catch (error) {
      toast(`Reply: ${error.message}`, "error");
    }
  }

  async setStatus(issue, action) {
    try {
      this.replaceIssue(await this.api.post(`/api/issues/${issue.id}/${action}`, {}));
    } catch (error) {
      toast(`Issue: ${error.message}`, "error");
    }
  }

  replaceIssue(updated) {
    const item = this.items.find((i) => i.kind === "issue" && i.issue.id === updated.id);
    if (item) item.issue = updated;
    this.render();
  }

  /** Leads: pin a new issue on the selected element (or the map centre) with a reason and a first comment. */
  openNewIssue() {
    const selected = this.tools.selected()[0];
    const elementId = selected ? /** @type {number} */ (selected.getId()) : null;
    const reason = h("select#issue-reason", {}, ...ISSUE_REASONS.map((r) => h("option", { value: r }, r.replaceAll("_", " "))));
    const comment = h("textarea#issue-comment", { rows: 3, placeholder: "What is wrong?", maxLength: 10000 });
    const submit = async () => {
      if (!comment.value.trim()) return;
      const body = { reason: reason.value, comment: comment.value };
      if (elementId) body.element_id = elementId;
      else body.point = this.view.getCenter();
      try {
        const issue = await this.api.post(`/api/sites/${this.siteId}/issues`, body);
        await this.refresh();
        this.focus(this.items.findIndex((i) => i.key === `issue-${issue.id}`));
      } catch (error) {
        toast(`New issue: ${error.message}`, "error");
      }
    };
    replaceChildren(
      this.thread,
      h("h4", {}, elementId ? `New issue on element #${elementId}` : "New issue at the map centre"),
      reason,
      comment,
      h("div.row", {}, h("button.small.primary#create-issue", { onclick: submit }, "Pin issue"), h("button.small", { onclick: () => this.renderThread() }, "Cancel")),
    );
    comment.focus();
  }
}
