// The lead view of a site: confidence queue, annotator figures with a chart, and jobs.
import { h } from "../dom.js";
import { FiguresCard } from "./figures.js";
import { JobsCard } from "./jobs.js";
import { QueueTable } from "./queue.js";

/**
 * @param {HTMLElement} container
 * @param {import("../api.js").Api} api
 * @param {number} siteId
 */
export async function mountLead(container, api, siteId) {
  const queue = new QueueTable(api, siteId);
  const figures = new FiguresCard(api, siteId);
  const jobs = new JobsCard(api, siteId);
  container.appendChild(h("div.lead-page", {}, h("div.lead-main", {}, queue.element), h("div.lead-side", {}, figures.element, jobs.element)));
  await Promise.all([queue.reload(0), figures.reload(), jobs.reload()]);
  return {
    destroy() {
      jobs.destroy();
    },
  };
}
