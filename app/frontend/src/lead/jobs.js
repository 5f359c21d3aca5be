// Jobs: launch an export, a retraining or a proposal refresh and watch their progress (polled while any job is
// unfinished). A server without a VMA registry answers retraining with 422; that message is shown as it comes, as
// is an export the server refuses (a field it needs, refined poses of a site without a reconstruction).
import { h, replaceChildren, shortTime, toast } from "../dom.js";

const POLL_MS = 1000;
const DONE = new Set(["succeeded", "failed", "cancelled"]);
/** The export formats (the backend's ExportFormat) and the options each takes. */
export const EXPORT_FORMATS = [
  { value: "cama", label: "CAMA release", dataset: true, cama: true },
  { value: "maptr", label: "MapTR vectors", dataset: true },
  { value: "nuscenes-cama", label: "nuScenes-CAMAv2", dataset: true },
  { value: "lanelet2", label: "Lanelet2 OSM", origin: true },
];

const option = (value, label) => h("option", { value }, label);

export class JobsCard {
  constructor(api, siteId) {
    this.api = api;
    this.siteId = siteId;
    this.timer = 0;
    this.message = h("div.job-message#job-message", { role: "status" });
    this.list = h("div.job-list#job-list");
    this.exportForm = this.exportOptions();
    this.element = h(
      "section.card.jobs#jobs",
      {},
      h("div.card-head", {}, h("h3", {}, "Jobs")),
      h(
        "div.row",
        {},
        this.exportForm.format,
        h("button.primary#launch-export", { onclick: () => this.launchExport() }, "Export"),
        h("button#launch-retrain", { onclick: () => this.launch("retrain", {}) }, "Retrain proposals"),
        h("button#launch-refresh", { onclick: () => this.launch("refresh_proposals", {}) }, "Refresh proposals"),
      ),
      this.exportForm.row,
      this.message,
      this.list,
    );
  }

  /** The export's options; those the chosen format does not take are hidden. */
  exportOptions() {
    const form = {
      format: h("select#export-format", { onchange: () => this.showExportOptions() }, ...EXPORT_FORMATS.map((f) => option(f.value, f.label))),
      poses: h("select#export-poses", { title: "Ego poses the export writes" }, option("refined", "refined poses"), option("coarse", "coarse (logged) poses")),
      mode: h("select#export-mode", { title: "CAMA map mode" }, option("clip", "clip maps (300 m)"), option("site", "site map (600 m)")),
      clipData: h("input#export-clip-data", { type: "checkbox" }),
      dataset: h("input#export-dataset", { placeholder: "data set folder on the server", size: 28 }),
      origin: h("input#export-origin", {
        placeholder: "origin lat, lon or nuScenes location",
        title: "Lanelet2: the map origin as lat, lon or a nuScenes location (e.g. boston-seaport); blank: the site's location",
        size: 24,
      }),
      projection: h(
        "select#export-projection",
        { title: "Lanelet2: how the site's frame lies on the Earth around the origin" },
        option("", "projection by origin"),
        option("local", "local tangent plane"),
        option("utm", "UTM grid"),
      ),
    };
    form.clipLabel = h("label.inline.small", { title: "Images, lane masks and attribute.json for CAMA's tools" }, form.clipData, "clip data");
    form.row = h("div.row.export-options#export-options", {}, form.poses, form.mode, form.clipLabel, form.dataset, form.origin, form.projection);
    this.exportForm = form;
    this.showExportOptions();
    return form;
  }

  showExportOptions() {
    const form = this.exportForm;
    const chosen = EXPORT_FORMATS.find((f) => f.value === form.format.value) || EXPORT_FORMATS[0];
    form.poses.hidden = !chosen.dataset;
    form.dataset.hidden = !chosen.dataset;
    form.mode.hidden = !chosen.cama;
    form.clipLabel.hidden = !chosen.cama;
    form.origin.hidden = !chosen.origin;
    form.projection.hidden = !chosen.origin;
  }

  /** The export job's params from the visible options; null (with the message shown) when the origin is unreadable. */
  exportParams() {
    const form = this.exportForm;
    const chosen = EXPORT_FORMATS.find((f) => f.value === form.format.value) || EXPORT_FORMATS[0];
    const params = { format: chosen.value };
    if (chosen.dataset) {
      params.poses = form.poses.value;
      if (form.dataset.value.trim()) params.dataset_root = form.dataset.value.trim();
    }
    if (chosen.cama) Object.assign(params, { mode: form.mode.value, with_clip_data: form.clipData.checked });
    if (chosen.origin) {
      const origin = form.origin.value.trim();
      if (/^[a-z][a-z-]*$/.test(origin)) params.origin_location = origin;
      else if (origin) {
        const parts = origin.split(",").map((part) => Number(part.trim()));
        if (parts.length !== 2 || parts.some((value) => !Number.isFinite(value))) {
          this.message.className = "job-message error";
          this.message.textContent = "export: origin: expected lat, lon in degrees (e.g. 1.2990, 103.7880) or a nuScenes location";
          return null;
        }
        params.origin_lat_lon = parts;
      }
      if (form.projection.value) params.projection = form.projection.value;
    }
    return params;
  }

  launchExport() {
    const params = this.exportParams();
    if (params) this.launch("export", params);
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
