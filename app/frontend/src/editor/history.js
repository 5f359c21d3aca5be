// Undo/redo stacks of saved transactions. A transaction lists, per element, the version before and after it,
// so undo restores the "before" version on the server and redo the "after" one (the server's restore keeps
// every version in the edit log, so nothing is ever erased).

const MAX_DEPTH = 500;

/**
 * @typedef {{id: number, from: number|null, to: number, created: boolean}} StepRecord
 * @typedef {{label: string, records: StepRecord[]}} Transaction
 */

export class History extends EventTarget {
  constructor() {
    super();
    /** @type {Transaction[]} */
    this.undoStack = [];
    /** @type {Transaction[]} */
    this.redoStack = [];
  }

  /** A new user action: push it and forget what could be redone. */
  push(transaction) {
    this.undoStack.push(transaction);
    if (this.undoStack.length > MAX_DEPTH) this.undoStack.shift();
    this.redoStack = [];
    this.changed();
  }

  /** @returns {Transaction|undefined} */
  takeUndo() {
    const transaction = this.undoStack.pop();
    this.changed();
    return transaction;
  }

  /** @returns {Transaction|undefined} */
  takeRedo() {
    const transaction = this.redoStack.pop();
    this.changed();
    return transaction;
  }

  /** Put a transaction on a stack again (after undo succeeded it goes to redo, and vice versa). */
  pushTo(stack, transaction) {
    (stack === "undo" ? this.undoStack : this.redoStack).push(transaction);
    this.changed();
  }

  changed() {
    this.dispatchEvent(new Event("change"));
  }
}
