// Keyboard shortcuts: one table drives both the key handling and the help overlay, so they never disagree.
import { h } from "../dom.js";

/**
 * @typedef {{keys: string[], label: string, group: string, run: () => void}} Shortcut
 */

/**
 * The key chord of an event: "Mod+Shift+z", "a", "?", "Delete"; Mod is Ctrl or Cmd. Shift is part of the
 * chord only for letters (so "?" stays "?").
 * @param {KeyboardEvent} event
 */
export function chordOf(event) {
  const key = event.key.length === 1 ? event.key.toLowerCase() : event.key;
  const parts = [];
  if (event.ctrlKey || event.metaKey) parts.push("Mod");
  if (event.altKey) parts.push("Alt");
  if (event.shiftKey && /^[a-z]$/.test(key)) parts.push("Shift");
  parts.push(key);
  return parts.join("+");
}

/** How a chord is shown: "Mod+Shift+z" -> "Ctrl+⇧Z". */
function keyLabel(chord) {
  return chord
    .replace("Mod+", "Ctrl+")
    .replace("Shift+", "⇧")
    .replace(/(^|\+|⇧)([a-z])$/, (_, before, letter) => before + letter.toUpperCase());
}

/** True when the event comes from a text field (shortcuts must not steal typing). */
function typing(event) {
  const target = /** @type {HTMLElement} */ (event.target);
  return target && (target.isContentEditable || ["INPUT", "TEXTAREA", "SELECT"].includes(target.tagName));
}

export class Shortcuts {
  /** @param {Shortcut[]} table */
  constructor(table) {
    this.table = table;
    this.byChord = new Map();
    for (const shortcut of table) for (const key of shortcut.keys) this.byChord.set(key, shortcut);
    this.overlay = null;
    this.onKey = (event) => this.handle(event);
    window.addEventListener("keydown", this.onKey);
  }

  handle(event) {
    if (typing(event)) return;
    const shortcut = this.byChord.get(chordOf(event));
    if (!shortcut) return;
    event.preventDefault();
    shortcut.run();
  }

  /** Show or hide the help overlay listing every shortcut by group. */
  toggleHelp() {
    if (this.overlay) {
      this.overlay.remove();
      this.overlay = null;
      return;
    }
    const groups = new Map();
    for (const shortcut of this.table) {
      if (!groups.has(shortcut.group)) groups.set(shortcut.group, []);
      groups.get(shortcut.group).push(shortcut);
    }
    const sections = [...groups].map(([group, shortcuts]) =>
      h(
        "section",
        {},
        h("h3", {}, group),
        h(
          "dl",
          {},
          ...shortcuts.flatMap((s) => [h("dt", {}, ...s.keys.map((k) => h("kbd", {}, keyLabel(k)))), h("dd", {}, s.label)]),
        ),
      ),
    );
    const extra = h(
      "section",
      {},
      h("h3", {}, "Mouse"),
      h(
        "dl",
        {},
        h("dt", {}, h("kbd", {}, "click")),
        h("dd", {}, "Select (shift-click adds)"),
        h("dt", {}, h("kbd", {}, "drag vertex")),
        h("dd", {}, "Move it (snaps to other vertices)"),
        h("dt", {}, h("kbd", {}, "drag segment")),
        h("dd", {}, "Insert a vertex"),
        h("dt", {}, h("kbd", {}, "Alt+click vertex")),
        h("dd", {}, "Delete it"),
        h("dt", {}, h("kbd", {}, "Ctrl+drag element")),
        h("dd", {}, "Move the selected elements whole"),
        h("dt", {}, h("kbd", {}, "click camera image")),
        h("dd", {}, "Enlarge it (Esc closes)"),
      ),
    );
    this.overlay = h(
      "div.overlay#help-overlay",
      { role: "dialog", "aria-label": "Keyboard shortcuts", onclick: (e) => e.target === this.overlay && this.toggleHelp() },
      h("div.overlay-card", {}, h("h2", {}, "Keyboard shortcuts"), h("div.help-grid", {}, ...sections, extra), h("p.muted", {}, "Press ? or Esc to close.")),
    );
    document.body.appendChild(this.overlay);
  }

  destroy() {
    window.removeEventListener("keydown", this.onKey);
    if (this.overlay) this.overlay.remove();
  }
}
