// DOM helpers. Every piece of text goes through textContent (never innerHTML), so user text is never markup.

/**
 * Build an element: h("button.primary", {onclick, title}, "Save", child...).
 * Strings among the children become text nodes; attributes starting with "on" become listeners.
 * @param {string} spec tag with optional .class and #id parts, in any order
 * @param {Record<string, unknown>} [attrs]
 * @param {...(Node|string|number|null|undefined|false)} children
 * @returns {HTMLElement}
 */
export function h(spec, attrs = {}, ...children) {
  const tag = spec.match(/^[a-z0-9]*/i)[0];
  const id = (spec.match(/#([\w-]+)/) || [])[1];
  const classes = [...spec.matchAll(/\.([\w-]+)/g)].map((m) => m[1]);
  const node = document.createElement(tag || "div");
  if (id) node.id = id;
  if (classes.length) node.className = classes.join(" ");
  for (const [key, value] of Object.entries(attrs || {})) {
    if (value === undefined || value === null || value === false) continue;
    if (key.startsWith("on") && typeof value === "function") {
      node.addEventListener(key.slice(2), /** @type {EventListener} */ (value));
    } else if (key === "dataset") {
      Object.assign(node.dataset, value);
    } else if (key in node && key !== "list" && key !== "form") {
      // properties such as value, checked, disabled
      /** @type {any} */ (node)[key] = value;
    } else {
      node.setAttribute(key, String(value === true ? "" : value));
    }
  }
  append(node, ...children);
  return node;
}

/**
 * Append children, turning strings and numbers into text nodes.
 * @param {Node} parent
 * @param {...(Node|string|number|null|undefined|false)} children
 */
export function append(parent, ...children) {
  for (const child of children.flat()) {
    if (child === null || child === undefined || child === false) continue;
    parent.appendChild(child instanceof Node ? child : document.createTextNode(String(child)));
  }
}

/**
 * Replace all children of a node.
 * @param {Node} parent
 * @param {...(Node|string|number|null|undefined|false)} children
 */
export function replaceChildren(parent, ...children) {
  while (parent.firstChild) parent.removeChild(parent.firstChild);
  append(parent, ...children);
}

/**
 * A short human time ("14:03:22") for an ISO timestamp.
 * @param {string} iso
 */
export function shortTime(iso) {
  const date = new Date(iso);
  return Number.isNaN(date.getTime()) ? iso : date.toLocaleString([], { dateStyle: "short", timeStyle: "medium" });
}

/**
 * Show a transient message in the toast area (text only).
 * @param {string} message
 * @param {"info"|"error"|"ok"} [kind]
 */
export function toast(message, kind = "info") {
  let area = document.getElementById("toasts");
  if (!area) {
    area = h("div#toasts");
    document.body.appendChild(area);
  }
  const item = h(`div.toast.${kind}`, { role: kind === "error" ? "alert" : "status" }, message);
  area.appendChild(item);
  setTimeout(() => item.remove(), kind === "error" ? 8000 : 3500);
}
