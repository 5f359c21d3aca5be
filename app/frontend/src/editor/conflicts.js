// The conflict banner: when a save lost a version race, the server's version is shown and the user's change is
// kept as an orange dashed draft, with "use mine" (save it over theirs) and "keep theirs" (drop it).
import Feature from "ol/Feature.js";
import { h, replaceChildren } from "../dom.js";
import { geometryFor } from "./elements.js";
import { Sync } from "./sync.js";
import { draftStyle } from "./styles.js";

export class ConflictBanner {
  /**
   * @param {import("./sync.js").Sync} sync
   * @param {import("ol/source/Vector.js").default} draftSource
   */
  constructor(sync, draftSource) {
    this.sync = sync;
    this.draftSource = draftSource;
    this.element = h("div.conflict-banner#conflict-banner", { role: "alert", hidden: true });
    sync.addEventListener("conflict", () => this.render());
  }

  render() {
    const drafts = [...this.sync.drafts.values()];
    this.draftSource.clear(true);
    for (const draft of drafts) {
      const step = draft.step;
      if (step.op !== "update") continue;
      const cls = step.body.class || draft.theirs.class;
      const feature = new Feature({ geometry: geometryFor(cls, step.body.points || draft.theirs.points) });
      feature.setStyle(draftStyle);
      this.draftSource.addFeature(feature);
    }
    this.element.hidden = drafts.length === 0;
    replaceChildren(
      this.element,
      ...drafts.map((draft) => {
        const theirs = draft.theirs;
        const what = draft.step.op === "delete" ? "your delete" : "your change";
        return h(
          "div.conflict-item",
          { dataset: { id: String(draft.id) } },
          h("strong", {}, `Conflict on element #${draft.id}. `),
          h(
            "span",
            {},
            "Someone else (",
            h("span.author", {}, theirs.author || "?"),
            `) saved version ${theirs.version} first. Their version is on the map; ${what} is kept (orange dashes).`,
          ),
          h("button.small.primary.use-mine", { onclick: () => this.sync.applyDraft(draft.id).then(() => this.render()) }, "Use mine"),
          Sync.mergedPoints(draft)
            ? h("button.small.merge-both", { onclick: () => this.sync.mergeDraft(draft.id).then(() => this.render()), title: "Keep their vertex moves and mine" }, "Merge both")
            : null,
          h("button.small.keep-theirs", { onclick: () => this.sync.discardDraft(draft.id) }, "Keep theirs"),
        );
      }),
    );
  }
}
