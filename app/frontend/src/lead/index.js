// The lead view of a site: confidence queue and the worst-reprojection queue beside it, annotator figures with a
// chart, and jobs.
import { h } from "../dom.js";
import { FiguresCard } from "./figures.js";
import { JobsCard } from "./jobs.js";
import { QueueTable } from "./queue.js";
import { ReprojectionQueue } from "./reprojection-queue.js";

/**
 * @param {HTMLElement} container
 * @param {import("../api.js").Api} api
 * @param {number} siteId
 */
export async function mountLead(container, api, siteId) {
  const queue = new QueueTable(api, siteId);
  const figures = new FiguresCard(api, siteId);
  const jobs = new JobsCard(api, siteId);
  const reprojection = new ReprojectionQueue(api, siteId);
  const side = h("div.lead-side", {}, reprojection.element, figures.element, jobs.element);
  container.appendChild(h("div.lead-page", {}, h("div.lead-main", {}, queue.element), side));
  await Promise.all([queue.reload(0), figures.reload(), jobs.reload(), reprojection.start()]);
  return {
    destroy() {
      jobs.destroy();
      reprojection.destroy();
    },
  };
}
