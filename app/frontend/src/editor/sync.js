// Autosave: every edit is saved at once through one serial queue, with the element's version (optimistic
// concurrency). A stale version (409) keeps the user's change as a draft beside the server's version and raises
// a conflict; nothing is lost on either side. Undo and redo restore saved versions through the same queue.
import { ApiError } from "../api.js";
import { toast } from "../dom.js";

/**
 * @typedef {{op: "create", body: {class: string, points: number[][]}}
 *   | {op: "update", id: number, body: {class?: string, points?: number[][]}}
 *   | {op: "delete", id: number}
 *   | {op: "review", id: number, state: string}} Step
 * @typedef {{id: number, step: Step, theirs: any, base: any}} Draft
 * @typedef {import("./history.js").StepRecord} StepRecord
 */

export class Sync extends EventTarget {
  /**
   * @param {import("../api.js").Api} api
   * @param {number} siteId
   * @param {import("./elements.js").ElementStore} store
   * @param {import("./history.js").History} history
   */
  constructor(api, siteId, store, history) {
    super();
    this.api = api;
    this.base = `/api/sites/${siteId}/elements`;
    this.store = store;
    this.history = history;
    this.chain = Promise.resolve();
    this.pending = 0;
    this.lastError = "";
    /** @type {Map<number, Draft>} the user's changes that lost a version race, by element id */
    this.drafts = new Map();
  }

  /** "saving", "saved", "conflict" or "error", for the status bar. */
  get status() {
    if (this.pending) return "saving";
    if (this.drafts.size) return "conflict";
    return this.lastError ? "error" : "saved";
  }

  emit(type, detail) {
    this.dispatchEvent(new CustomEvent(type, { detail }));
  }

  /** Run a task after every earlier one (saves never overtake each other, so versions chain). */
  enqueue(task) {
    this.pending += 1;
    this.emit("status");
    const run = this.chain.then(task).finally(() => {
      this.pending -= 1;
      this.emit("status");
    });
    this.chain = run.catch(() => undefined);
    return run;
  }

  /**
   * Save one user action (one or more steps) and record it for undo.
   * @param {string} label
   * @param {Step[]} steps
   * @returns {Promise<StepRecord[]|null>} the saved steps, or null when one failed
   */
  commit(label, steps) {
    return this.enqueue(async () => {
      const records = [];
      try {
        for (const step of steps) records.push(await this.execute(step));
        this.lastError = "";
        return records;
      } catch (error) {
        this.failed(error, steps[records.length]);
        return null;
      } finally {
        if (records.length) this.history.push({ label, records });
        this.emit("changed", { label });
      }
    });
  }

  /** Send one step with the version last read; the server's answer becomes the client's copy. */
  async execute(step) {
    if (step.op === "create") {
      const element = await this.api.post(this.base, { ...step.body, source: "human" });
      this.store.upsert(element);
      return { id: element.id, from: null, to: element.version, created: true };
    }
    const current = this.store.get(step.id);
    const version = current.version;
    const path = `${this.base}/${step.id}`;
    let element;
    if (step.op === "update") element = await this.api.patch(path, { version, ...step.body });
    else if (step.op === "delete") element = await this.api.del(path, { version });
    else element = await this.api.post(`${path}/review`, { state: step.state, version });
    this.store.upsert(element);
    return { id: step.id, from: version, to: element.version, created: false };
  }

  /** A failed step: a stale version becomes a draft + conflict; anything else is shown and undone locally. */
  failed(error, step) {
    const current = error instanceof ApiError && error.body ? error.body.current : null;
    const id = step && step.op !== "create" ? step.id : null;
    if (error instanceof ApiError && error.isConflict && current && id !== null && current.version !== this.store.get(id).version) {
      const base = this.store.get(id);
      this.store.upsert(current);
      if (step.op !== "review") this.drafts.set(id, { id, step, theirs: current, base });
      this.emit("conflict", { id, current, draft: this.drafts.get(id) || null });
      return;
    }
    this.lastError = error.message;
    toast(error.message, "error");
    if (id !== null && this.store.get(id)) this.store.upsert(this.store.get(id));
  }

  /** Apply a kept draft over the server's version (the other side's version stays in the edit log). */
  applyDraft(id) {
    const draft = this.drafts.get(id);
    if (!draft) return Promise.resolve(null);
    this.drafts.delete(id);
    return this.commit("Apply my version", [draft.step]);
  }

  /**
   * Both sides' vertex moves together, when neither side added or removed vertices: each vertex I moved takes
   * my position, every other vertex keeps theirs. Null when the drafts cannot be combined that way.
   * @param {Draft} draft
   */
  static mergedPoints(draft) {
    const mine = draft.step.op === "update" ? draft.step.body.points : null;
    const base = draft.base.points;
    const theirs = draft.theirs.points;
    if (!mine || mine.length !== base.length || theirs.length !== base.length) return null;
    if (draft.theirs.class !== draft.base.class) return null;
    return mine.map((p, i) => (Math.abs(p[0] - base[i][0]) > 1e-4 || Math.abs(p[1] - base[i][1]) > 1e-4 ? p : theirs[i]));
  }

  /** Save the merge of both sides' vertex moves (see mergedPoints). */
  mergeDraft(id) {
    const draft = this.drafts.get(id);
    const points = draft ? Sync.mergedPoints(draft) : null;
    if (!points) return Promise.resolve(null);
    this.drafts.delete(id);
    return this.commit("Merge both versions", [{ op: "update", id, body: { points } }]);
  }

  /** Drop a kept draft: the server's version stands. */
  discardDraft(id) {
    this.drafts.delete(id);
    this.emit("status");
    this.emit("conflict", { id, current: this.store.get(id), draft: null });
  }

  /** Undo the last saved action (after pending saves) by restoring each element's earlier version. */
  undo() {
    return this.replay("undo");
  }

  /** Redo the last undone action (after pending saves) by restoring each element's later version. */
  redo() {
    return this.replay("redo");
  }

  /** Take the transaction inside the queue, so an undo pressed during a save undoes that save. */
  replay(direction) {
    return this.enqueue(async () => {
      const transaction = direction === "undo" ? this.history.takeUndo() : this.history.takeRedo();
      if (!transaction) return false;
      const records = direction === "undo" ? [...transaction.records].reverse() : transaction.records;
      try {
        for (const record of records) {
          const version = this.store.get(record.id).version;
          const path = `${this.base}/${record.id}`;
          const element =
            direction === "undo" && record.created
              ? await this.api.del(path, { version })
              : await this.api.post(`${path}/history/${direction === "undo" ? record.from : record.to}/restore`, { version });
          this.store.upsert(element);
        }
        this.history.pushTo(direction === "undo" ? "redo" : "undo", transaction);
        this.lastError = "";
        toast(`${direction === "undo" ? "Undone" : "Redone"}: ${transaction.label}`, "ok");
        return true;
      } catch (error) {
        this.history.pushTo(direction, transaction);
        const current = error instanceof ApiError && error.body ? error.body.current : null;
        if (current) this.store.upsert(current);
        this.lastError = `${direction} failed: ${error.message}`;
        toast(`Cannot ${direction} "${transaction.label}": ${error.message}`, "error");
        return false;
      } finally {
        this.emit("changed", { label: direction });
      }
    });
  }
}
