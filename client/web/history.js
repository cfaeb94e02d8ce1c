// This tab's history: every result the page has shown (a Run, a kept variation, a tile, an
// extracted alpha) kept in IndexedDB (store.js), so that a reload keeps it, and shown under
// the result newest first as a strip of thumbnails, each to show again, download, or take the
// options of into the form again.

import { MemoryStore, openHistoryStore } from "./store.js";

const $ = (id) => document.getElementById(id);

/** Results kept at most: past it, the oldest is dropped. */
export const MAX_ENTRIES = 30;

/** The longest side of a thumbnail, in pixels. */
const THUMB_SIDE = 96;

/** Operations that have no radio of their own, by the name the page records them under. */
const OTHER_OPERATIONS = { extract: "Extract alpha" };

/** Why an old result's seams are not shown. */
const NO_SEAMS = "A result from the history: its seams are not kept. Run it again (Use these " +
  "options again, then Run) to see them.";

/** The history of this page (its one :class:`History`), for the console and the tests. */
let current = null;

/** The page's :class:`History` (null before the page has made it). */
export function pageHistory() {
  return current;
}

/**
 * What a request sent, for the history: ``{options, inputs}``, its options object (its
 * "options" part) and the names of the files it sent (empty parts left out), each once.
 * ``body``: the FormData, or a promise of it.
 */
export async function sentIn(body) {
  const form = await body;
  const options = JSON.parse(form.get("options") || "{}");
  const files = [...form.values()].filter((value) => value instanceof File && value.size);
  return { options, inputs: [...new Set(files.map((file) => file.name))] };
}

/** A PNG thumbnail of the image ``blob``, its longer side at most 96 pixels. */
export async function thumbnailOf(blob) {
  const bitmap = await createImageBitmap(blob);
  const scale = Math.min(1, THUMB_SIDE / Math.max(bitmap.width, bitmap.height));
  const canvas = document.createElement("canvas");
  canvas.width = Math.max(1, Math.round(bitmap.width * scale));
  canvas.height = Math.max(1, Math.round(bitmap.height * scale));
  const context = canvas.getContext("2d");
  context.imageSmoothingQuality = "high";
  context.drawImage(bitmap, 0, 0, canvas.width, canvas.height);
  bitmap.close();
  return new Promise((resolve, reject) => {
    canvas.toBlob((png) => (png ? resolve(png) : reject(new Error("no thumbnail"))), "image/png");
  });
}

/**
 * The history entry of a result shown with ``viewer.show(shown)`` (viewer.js): the operation
 * ``op``, what was sent (``sent``: a promise of :func:`sentIn`), its ``seed`` (null: none),
 * and the result's ``width`` and ``height``.
 */
export async function entryOf(op, shown, { sent, seed, width, height }) {
  const { options, inputs } = (await sent) || { options: {}, inputs: [] };
  return {
    time: Date.now(),
    operation: op,
    options,
    inputs,
    result: shown.result,
    resultName: shown.resultName,
    width,
    height,
    seed: Number.isInteger(seed) ? seed : null,
    stats: shown.stats || [],
    layout: shown.layout || null,
    layoutName: shown.layout ? shown.layoutName : null,
    input: shown.input || null,
    display: {
      view: shown.view || null,
      inputLabel: shown.inputLabel || null,
      resultLabel: shown.resultLabel || null,
      downloadLabel: shown.downloadLabel || null,
    },
  };
}

/** The operation's radio on the form, or null (an extraction has none). */
function radioOf(op) {
  return document.querySelector(`input[name="operation"][value="${CSS.escape(op)}"]`);
}

/** "Synthesize": the words of the operation's radio. */
function operationWords(op) {
  return radioOf(op)?.closest("label")?.textContent.trim() || OTHER_OPERATIONS[op] || op;
}

/** "12:03:04" today, "3/5/2025, 12:03:04" on another day. */
function timeWords(time) {
  const date = new Date(time);
  const today = date.toDateString() === new Date().toDateString();
  return today ? date.toLocaleTimeString() : date.toLocaleString();
}

/** "Synthesize, 96 × 96, seed 3": an entry in a few words. */
export function describeEntry(entry) {
  const seed = entry.seed === null ? "" : `, seed ${entry.seed}`;
  return `${operationWords(entry.operation)}, ${entry.width} × ${entry.height}${seed}`;
}

/** The strip of results in ``#history``: kept in the store, drawn newest first, each entry
 * shown again, downloaded, its options reused or removed; "Clear history" for all. */
export class History {
  /**
   * The strip in ``#history``. ``show(shown)``: show a stored result in the viewer (the
   * arguments of ``viewer.show``); ``reuse(op, options)``: select the operation and set the
   * form to those options.
   */
  constructor({ show, reuse }) {
    current = this;
    this.show = show;
    this.reuse = reuse;
    this.list = $("history-list");
    this.info = $("history-info");
    this.clearButton = $("history-clear");
    this.store = null;
    this.unavailable = ""; // why the history is not kept past the page
    this.failure = ""; // what went wrong in the last change, said once
    this.title = $("history-title");
    this.title.tabIndex = -1; // where the focus goes once the last entry is removed
    this.busy = false;
    this.urls = []; // the object URLs of the strip drawn
    this.entries = [];
    // One change at a time, in order (an entry added while another is removed, say).
    this.queue = Promise.resolve();
    this.clearButton.addEventListener("click", () => this.clear());
    this.list.addEventListener("click", (event) => this.act(event));
    this.ready = this.change(() => this.open());
  }

  /** Run ``work`` after every change asked before it, then draw the strip anew. */
  change(work, focus = null) {
    this.queue = this.queue.then(work).catch((error) => {
      this.failure = `The history could not be changed: ${error.message}`;
    }).then(() => this.render(focus)).catch((error) => {
      this.info.textContent = `The history could not be shown: ${error.message}`;
    });
    return this.queue;
  }

  async open() {
    try {
      this.store = await openHistoryStore();
    } catch (error) {
      this.store = new MemoryStore();
      this.unavailable = `This browser does not keep the history (${error.message}; a private ` +
        "window?): the results are listed here until the page is reloaded.";
    }
  }

  /**
   * Add a result (an entry of :func:`entryOf`, or a promise of one), with a thumbnail made
   * of it when it has none; the oldest entries past :data:`MAX_ENTRIES` are dropped.
   * Resolves once the strip shows it (never rejects: a failure is said in the strip).
   */
  add(entry) {
    return this.change(async () => {
      const record = { ...(await entry) };
      if (!record.thumbnail) record.thumbnail = await thumbnailOf(record.result).catch(() => null);
      await this.store.add(record, MAX_ENTRIES);
    });
  }

  /** Take the entry ``id`` out. */
  remove(id, focus) {
    return this.change(() => this.store.remove(id), focus);
  }

  /** Take every entry out. */
  clear() {
    return this.change(() => this.store.clear(), { clear: true });
  }

  /** While a job runs, "Show" waits (the job's result is about to be shown). */
  setBusy(busy) {
    this.busy = busy;
    for (const button of this.list.querySelectorAll(".history-show")) button.disabled = busy;
  }

  /** A click in the strip: the entry's button. */
  act(event) {
    const button = event.target.closest("button[data-action]");
    const item = button?.closest("li[data-id]");
    if (!item) return;
    const index = this.entries.findIndex((entry) => String(entry.id) === item.dataset.id);
    const entry = this.entries[index];
    if (!entry) return;
    if (button.dataset.action === "show") this.showEntry(entry);
    else if (button.dataset.action === "reuse") this.reuse(entry.operation, entry.options);
    else if (button.dataset.action === "remove") this.remove(entry.id, { index });
  }

  /** Show a stored result in the viewer, as it was shown (its seams excepted). */
  async showEntry(entry) {
    const display = entry.display || {};
    try {
      await this.show({
        result: entry.result,
        resultName: entry.resultName,
        downloadLabel: display.downloadLabel || undefined,
        input: entry.input || entry.result,
        inputLabel: entry.input ? display.inputLabel || undefined : "Result",
        resultLabel: display.resultLabel || undefined,
        view: display.view || "single",
        layout: entry.layout,
        layoutName: entry.layoutName,
        companions: [],
        loadSeams: null,
        noSeams: NO_SEAMS,
        stats: [["from the history", timeWords(entry.time)], ...entry.stats],
      });
    } catch (error) {
      this.info.textContent = `That result could not be shown: ${error.message}`;
    }
  }

  /** Draw the strip from the store, newest first; ``focus`` says where the focus goes after
   * a removal ({index}: the entry now there, else the one before; {clear: true}: none left). */
  async render(focus = null) {
    let entries = [];
    try {
      entries = this.store ? await this.store.all() : [];
    } catch (error) {
      this.failure = `The history could not be read: ${error.message}`;
    }
    for (const url of this.urls.splice(0)) URL.revokeObjectURL(url);
    this.entries = entries;
    this.list.replaceChildren(...entries.map((entry) => this.item(entry)));
    this.list.hidden = !entries.length;
    this.clearButton.disabled = !entries.length;
    const kept = entries.length
      ? `${entries.length} result${entries.length === 1 ? "" : "s"}, newest first (at most ` +
        `${MAX_ENTRIES}: then the oldest is dropped).`
      : "Each result shown above is added here, newest first.";
    const where = this.store?.persistent ? "Kept in this browser, also after a reload." : "";
    this.info.textContent = [this.unavailable, this.failure, kept, where].filter(Boolean)
      .join(" ");
    this.failure = ""; // said once
    if (focus) {
      const items = [...this.list.children];
      const item = items[Math.min(focus.index ?? 0, items.length - 1)];
      (item?.querySelector(".history-show") || this.title).focus();
    }
  }

  objectUrl(blob) {
    const url = URL.createObjectURL(blob);
    this.urls.push(url);
    return url;
  }

  /** One entry of the strip: its thumbnail, caption and buttons. */
  item(entry) {
    const words = describeEntry(entry);
    const when = timeWords(entry.time);
    const item = document.createElement("li");
    item.className = "history-entry";
    item.dataset.id = String(entry.id);
    item.dataset.operation = entry.operation;
    if (entry.seed !== null) item.dataset.seed = String(entry.seed);
    const thumb = document.createElement("img");
    thumb.className = "history-thumb";
    thumb.src = this.objectUrl(entry.thumbnail || entry.result);
    thumb.alt = ""; // the caption beside it says what it is
    thumb.decoding = "async";
    const caption = document.createElement("p");
    caption.className = "history-caption";
    const what = document.createElement("span");
    what.className = "history-what";
    what.textContent = words;
    const time = document.createElement("time");
    time.dateTime = new Date(entry.time).toISOString();
    time.textContent = when;
    caption.append(what, time);
    if (entry.inputs?.length) {
      const inputs = document.createElement("span");
      inputs.className = "history-inputs";
      inputs.textContent = entry.inputs.join(", ");
      caption.append(inputs);
    }
    const options = document.createElement("span");
    options.className = "history-options";
    options.textContent = optionsWords(entry.options);
    caption.append(options);
    const actions = document.createElement("div");
    actions.className = "history-actions";
    const label = `${words}, ${when}`;
    const show = button("show", "Show", `Show ${label}`);
    show.disabled = this.busy;
    const download = document.createElement("a");
    download.className = "history-download";
    download.href = this.objectUrl(entry.result);
    download.download = entry.resultName;
    download.textContent = "Download";
    download.setAttribute("aria-label", `Download ${entry.resultName}`);
    actions.append(show, download);
    if (radioOf(entry.operation)) {
      actions.append(button("reuse", "Use these options again",
        `Use these options again: ${label}`));
    }
    actions.append(button("remove", "Remove", `Remove ${label}`));
    item.append(thumb, caption, actions);
    return item;
  }
}

/** Options the caption already says (the size, the seed). */
const IN_CAPTION = new Set(["width", "height", "seed"]);

/**
 * The options an entry was made with, beyond its size and seed, as sent (only those that
 * differ from the service's defaults): "block 32; tileable both", or "default options".
 */
export function optionsWords(options) {
  const shown = Object.entries(options || {}).filter(([name]) => !IN_CAPTION.has(name));
  if (!shown.length) return "default options";
  const text = (value) => (Array.isArray(value) ? value.map(text).join(", ")
    : value !== null && typeof value === "object" ? JSON.stringify(value) : String(value));
  return shown.map(([name, value]) => `${name} ${text(value)}`).join("; ");
}

/** A button of an entry: its ``action``, visible ``text`` and the name read out. */
function button(action, text, label) {
  const made = document.createElement("button");
  made.type = "button";
  made.className = `history-${action}`;
  made.dataset.action = action;
  made.textContent = text;
  made.setAttribute("aria-label", label);
  return made;
}
