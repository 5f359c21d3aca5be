// Entry point: the app shell (top bar) and a hash router over the login, site list, editor and lead views.
import "ol/ol.css";
import "./style.css";
import { Api } from "./api.js";
import { h, replaceChildren } from "./dom.js";
import { mountLogin } from "./login.js";
import { mountSites } from "./sites.js";
import { mountEditor } from "./editor/index.js";
import { mountLead } from "./lead/index.js";
import { ReviewLink } from "./review-link.js";

/**
 * Parse the hash: "#/site/3/lead?class=divider" -> {parts: ["site","3","lead"], params}.
 * @returns {{parts: string[], params: URLSearchParams}}
 */
function parseRoute() {
  const raw = window.location.hash.replace(/^#\/?/, "");
  const [path, search] = raw.split("?");
  return { parts: path.split("/").filter(Boolean), params: new URLSearchParams(search || "") };
}

class App {
  constructor(root) {
    this.api = new Api();
    this.root = root;
    /** @type {{destroy: () => void}|null} */
    this.view = null;
    this.routeCount = 0;
    this.userBox = h("div.user");
    this.nav = h("nav.tabs");
    this.reviewLink = new ReviewLink();
    this.content = h("main.content");
    const brand = h("a.brand", { href: "#/sites", title: "Sites" }, h("span.logo", {}, "◆"), "CAMA Studio");
    replaceChildren(root, h("header.topbar", {}, brand, this.nav, this.userBox), this.content);
    window.addEventListener("hashchange", () => this.route());
    window.addEventListener("cama:logout", () => this.logout());
    window.addEventListener("cama:selection", (event) => this.reviewLink.select(/** @type {CustomEvent} */ (event).detail.ids));
  }

  async start() {
    await this.reviewLink.configure(this.api);
    if (this.api.token) {
      try {
        this.api.me = await this.api.get("/api/auth/me");
      } catch {
        this.api.setToken(null);
      }
    }
    await this.route();
  }

  logout() {
    this.api.logout();
    window.location.hash = "#/login";
  }

  /** Top bar: the tabs of the current site (and its 3D review when one is served) and the user with a log-out button. */
  renderChrome(siteId, active) {
    const me = this.api.me;
    const tabs = [];
    if (siteId !== null) {
      tabs.push(h(`a.tab${active === "editor" ? ".active" : ""}`, { href: `#/site/${siteId}` }, "Editor"));
      if (me && me.role !== "annotator") {
        tabs.push(h(`a.tab${active === "lead" ? ".active" : ""}`, { href: `#/site/${siteId}/lead` }, "Lead"));
      }
      tabs.push(this.reviewLink.forSite(siteId));
    }
    replaceChildren(this.nav, ...tabs);
    if (me) {
      const name = h("span.username", { title: `role: ${me.role}` }, me.username);
      const role = h("span.role", {}, me.role);
      const out = h("button.ghost#logout", { onclick: () => this.logout() }, "Log out");
      replaceChildren(this.userBox, name, role, out);
    } else {
      replaceChildren(this.userBox);
    }
  }

  /** Show the view of the current hash; a view whose mount finishes after a newer route is dropped. */
  async route() {
    const ticket = ++this.routeCount;
    const { parts, params } = parseRoute();
    if (this.view) this.view.destroy();
    this.view = null;
    const host = h("div.view-host");
    replaceChildren(this.content, host);
    let view;
    if (!this.api.me) {
      this.renderChrome(null, "");
      view = mountLogin(host, this.api, () => {
        if (parts[0] === "login" || !parts.length) window.location.hash = "#/sites";
        else this.route();
      });
    } else if (parts[0] === "site" && /^\d+$/.test(parts[1] || "")) {
      const siteId = Number(parts[1]);
      const lead = parts[2] === "lead";
      this.renderChrome(siteId, lead ? "lead" : "editor");
      view = await (lead ? mountLead : mountEditor)(host, this.api, siteId, params);
    } else {
      this.renderChrome(null, "");
      view = await mountSites(host, this.api);
    }
    if (ticket === this.routeCount) this.view = view;
    else {
      view.destroy();
      host.remove();
    }
  }
}

new App(document.getElementById("app")).start();
