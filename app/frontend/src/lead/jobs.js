// Jobs: launch an export, a retraining or a proposal refresh and watch their progress (polled while any job is
// unfinished). A server without a VMA registry answers retraining with 422; that message is shown as it comes.
import { h, replaceChildren, shortTime, toast } from "../dom.js";

const POLL_MS = 1000;
const DONE = new Set(["succeeded", "failed", "cancelled"]);

export class JobsCard {
  constructor(api, siteId) {
    this.api = api;
    this.siteId = siteId;
    this.timer = 0;
    this.message = h("div.job-message#job-message", { role: "status" });
    this.list = h("div.job-list#job-list");
    const format = h("select#export-format", {}, h("option", { value: "cama" }, "CAMA release"));
    this.element = h(
      "section.card.jobs#jobs",
      {},
      h("div.card-head", {}, h("h3", {}, "Jobs")),
      h(
        "div.row",
        {},
        format,
        h("button.primary#launch-export", { onclick: () => this.launch("export", { format: format.value }) }, "Export"),
        h("button#launch-retrain", { onclick: () => this.launch("retrain", {}) }, "Retrain proposals"),
        h("button#launch-refresh", { onclick: () => this.launch("refresh_proposals", {}) }, "Refresh proposals"),
      ),
      this.message,
      this.list,
    );
  }

  async launch(kind, params) {
    this.message.className = "job-message";
    this.message.textContent = `Submitting ${kind}…`;
    try {
      const job = await this.api.post(`/api/sites/${this.siteId}/jobs`, { kind, params });
      this.message.textContent = `${kind} job #${job.id} queued`;
      this.reload();
    } catch (error) {
      this.message.className = "job-message error";
      this.message.textContent = `${kind}: ${error.message}`;
    }
  }

  async reload() {
    clearTimeout(this.timer);
    try {
      const jobs = await this.api.get(`/api/sites/${this.siteId}/jobs`, { limit: 20 });
      replaceChildren(this.list, ...jobs.map((job) => this.row(job)));
      if (!jobs.length) this.list.appendChild(h("p.muted", {}, "No jobs yet."));
      if (jobs.some((job) => !DONE.has(job.state))) this.timer = setTimeout(() => this.reload(), POLL_MS);
    } catch (error) {
      toast(`Jobs: ${error.message}`, "error");
    }
  }

  row(job) {
    const pct = Math.round(job.progress * 100);
    const download = job.download_url ? h("a.small.download", { href: "#", onclick: (e) => (e.preventDefault(), this.download(job)) }, "Download") : null;
    return h(
      `div.job.${job.state}`,
      { dataset: { id: String(job.id), state: job.state } },
      h("div.job-head", {}, h("strong", {}, `#${job.id} ${job.kind}`), h(`span.state.${job.state}`, {}, job.state), h("span.muted.small", {}, shortTime(job.created_at)), download),
      h("div.progress", { title: `${pct}%` }, h("div.progress-fill", { style: `width: ${pct}%` })),
      h("div.muted.small.job-text", {}, `${pct}% ${job.message || ""}`),
    );
  }

  /** Downloads need the token, so fetch the file and hand the browser a blob link. */
  async download(job) {
    try {
      const response = await fetch(job.download_url, { headers: this.api.authHeaders() });
      if (!response.ok) throw new Error(`HTTP ${response.status}`);
      const url = URL.createObjectURL(await response.blob());
      const link = h("a", { href: url, download: `job-${job.id}.zip` });
      document.body.appendChild(link);
      link.click();
      link.remove();
      setTimeout(() => URL.revokeObjectURL(url), 10000);
    } catch (error) {
      toast(`Download: ${error.message}`, "error");
    }
  }

  destroy() {
    clearTimeout(this.timer);
  }
}
