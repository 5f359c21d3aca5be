// Entry point: the app shell (top bar) and a hash router over the login, site list, editor and lead views.
import "ol/ol.css";
import "./style.css";
import { Api } from "./api.js";
import { h, replaceChildren } from "./dom.js";
import { mountLogin } from "./login.js";
import { mountSites } from "./sites.js";
import { mountEditor } from "./editor/index.js";
import { mountLead } from "./lead/index.js";

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
    this.userBox = h("div.user");
    this.nav = h("nav.tabs");
    this.content = h("main.content");
    const brand = h("a.brand", { href: "#/sites", title: "Sites" }, h("span.logo", {}, "◆"), "CAMA Studio");
    replaceChildren(root, h("header.topbar", {}, brand, this.nav, this.userBox), this.content);
    window.addEventListener("hashchange", () => this.route());
    window.addEventListener("cama:logout", () => this.logout());
  }

  async start() {
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

  /** Top bar: the tabs of the current site and the user with a log-out button. */
  renderChrome(siteId, active) {
    const me = this.api.me;
    const tabs = [];
    if (siteId !== null) {
      tabs.push(h(`a.tab${active === "editor" ? ".active" : ""}`, { href: `#/site/${siteId}` }, "Editor"));
      if (me && me.role !== "annotator") {
        tabs.push(h(`a.tab${active === "lead" ? ".active" : ""}`, { href: `#/site/${siteId}/lead` }, "Lead"));
      }
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

  async route() {
    const { parts, params } = parseRoute();
    if (this.view) this.view.destroy();
    this.view = null;
    replaceChildren(this.content);
    if (!this.api.me) {
      this.renderChrome(null, "");
      this.view = mountLogin(this.content, this.api, () => {
        window.location.hash = parts.length && parts[0] !== "login" ? window.location.hash : "#/sites";
        this.route();
      });
      return;
    }
    if (parts[0] === "site" && /^\d+$/.test(parts[1] || "")) {
      const siteId = Number(parts[1]);
      const lead = parts[2] === "lead";
      this.renderChrome(siteId, lead ? "lead" : "editor");
      const mount = lead ? mountLead : mountEditor;
      this.view = await mount(this.content, this.api, siteId, params);
      return;
    }
    this.renderChrome(null, "");
    this.view = await mountSites(this.content, this.api);
  }
}

new App(document.getElementById("app")).start();
