// The site list: every registered site with its element counts; click one to open the editor.
import { h, toast } from "./dom.js";

/**
 * @param {HTMLElement} container
 * @param {import("./api.js").Api} api
 */
export async function mountSites(container, api) {
  const list = h("div.site-grid");
  container.appendChild(h("div.page", {}, h("h2", {}, "Sites"), list));
  try {
    const sites = await api.get("/api/sites");
    if (!sites.length) list.appendChild(h("p.muted", {}, "No site registered yet (a lead registers one)."));
    for (const site of sites) {
      const e = site.extent;
      const size = `${(e.xmax - e.xmin).toFixed(0)} m × ${(e.ymax - e.ymin).toFixed(0)} m`;
      list.appendChild(
        h(
          "a.site-card",
          { href: `#/site/${site.id}`, dataset: { siteId: String(site.id) } },
          h("strong", {}, site.name),
          h("span.muted", {}, `#${site.id} · ${size}`),
        ),
      );
    }
  } catch (error) {
    toast(`Sites: ${error.message}`, "error");
  }
  return { destroy() {} };
}
