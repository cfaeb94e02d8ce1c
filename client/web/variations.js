// "Make 4 variations": the job Run would send, four times with four fresh random seeds, all
// at once, and a grid under the result with a cell per seed: its progress while it runs, then
// a thumbnail of the result, its seed, its download (the service's file name) and "Keep this
// one". The jobs go through the page's one submit-and-follow path (app.js's submitJob);
// keeping one is app.js's too (its seed into the form, its job shown as a Run's result).

import { ApiError, getFile, statusWords } from "./api.js";

const $ = (id) => document.getElementById(id);

/** Variations made by one click. */
export const VARIATIONS = 4;

/** Seeds drawn: below 2^31, as the seed's "Another seed" (options.js). */
const SEEDS = 2 ** 31;

/** ``count`` distinct random seeds below 2^31, drawn with crypto.getRandomValues. */
export function freshSeeds(count = VARIATIONS) {
  const seeds = new Set();
  const draw = new Uint32Array(count);
  while (seeds.size < count) {
    crypto.getRandomValues(draw);
    for (const value of draw) if (seeds.size < count) seeds.add(value % SEEDS);
  }
  return [...seeds];
}

/** A problem in a few words: the service's detail and code, or the error's message. */
function problemWords(error) {
  return error instanceof ApiError ? error.describe() : error.message || String(error);
}

/** One variation's cell: its job followed, then its result. */
class Cell {
  /** ``job``: {seed, options, body, texture}; ``keep(cell)``: "Keep this one" (or a click on
   * the thumbnail). */
  constructor(job, keep) {
    this.job = job;
    this.id = null;
    this.snapshot = null; // the job's final status document once done
    this.fraction = 0;
    this.ended = false;
    const seed = job.seed;
    this.element = document.createElement("li");
    this.element.className = "variation";
    this.element.dataset.seed = String(seed);
    this.element.dataset.status = "submitting";
    this.picture = document.createElement("div");
    this.picture.className = "variation-picture";
    this.progress = document.createElement("progress");
    this.progress.max = 100;
    this.progress.value = 0;
    this.progress.setAttribute("aria-label", `Progress of seed ${seed}`);
    this.picture.append(this.progress);
    const caption = document.createElement("p");
    caption.className = "variation-seed";
    caption.textContent = `seed ${seed}`;
    this.status = document.createElement("p");
    this.status.className = "variation-status hint";
    this.status.textContent = "submitting";
    this.download = document.createElement("a");
    this.download.className = "variation-download";
    this.download.textContent = "Download";
    this.download.hidden = true;
    this.keepButton = document.createElement("button");
    this.keepButton.type = "button";
    this.keepButton.className = "variation-keep";
    this.keepButton.textContent = "Keep this one";
    this.keepButton.setAttribute("aria-label", `Keep this one: seed ${seed}`);
    this.keepButton.disabled = true;
    this.keepButton.addEventListener("click", () => keep(this));
    const actions = document.createElement("div");
    actions.className = "variation-actions";
    actions.append(this.download, this.keepButton);
    this.element.append(this.picture, caption, this.status, actions);
    this.keep = keep;
  }

  /** A status event of the job (or its status document). */
  report(data) {
    if (typeof data.progress === "number") {
      this.fraction = Math.min(1, Math.max(0, data.progress));
      this.progress.value = Math.round(this.fraction * 100);
    }
    const words = statusWords(data);
    if (words) this.setStatus(data.status, words);
  }

  setStatus(status, words) {
    this.element.dataset.status = status;
    this.status.textContent = words;
  }

  /** The job's id, once the service answered. */
  setJob(id) {
    this.id = id;
    this.element.dataset.job = id;
    this.setStatus("queued", "queued");
  }

  /** Done: its result ``file`` ({blob, name}) shown, downloadable and keepable. */
  finish(snapshot, file, url) {
    this.snapshot = snapshot;
    this.end("done", `done, ${snapshot.width} × ${snapshot.height}`);
    const image = document.createElement("img");
    image.className = "variation-image";
    image.src = url;
    image.alt = `Variation with seed ${this.job.seed}`;
    image.title = "Keep this one";
    image.addEventListener("click", () => {
      if (!this.keepButton.disabled) this.keep(this);
    });
    this.picture.replaceChildren(image);
    this.download.href = url;
    this.download.download = file.name;
    this.download.title = file.name;
    this.download.setAttribute("aria-label", `Download ${file.name}`);
    this.download.hidden = false;
  }

  /** Over without a result: ``status`` "failed" or "cancelled", and why. */
  end(status, words) {
    this.ended = true;
    this.fraction = 1;
    this.progress.value = 100;
    this.setStatus(status, words);
    if (status !== "done") this.picture.replaceChildren();
  }
}

/** "Make 4 variations" and its grid: the cells of the last variations made, one to keep. */
export class Variations {
  /**
   * The "Make 4 variations" button (``#variations-run``) and the grid (``#variations``).
   * ``start()``: the button was pressed (app.js builds the requests and calls ``run``);
   * ``keep(variation)``: one was kept (``variation``: {op, key, seed, options, body, texture,
   * snapshot}).
   */
  constructor({ start, keep }) {
    this.button = $("variations-run");
    this.section = $("variations");
    this.grid = $("variations-grid");
    this.keep = keep;
    this.available = true;
    this.busy = false;
    this.cells = [];
    this.urls = [];
    this.button.addEventListener("click", start);
  }

  /** Whether the operation chosen can make variations (it has a seed and runs as a job). */
  setAvailable(available) {
    this.available = available;
    this.button.hidden = !available;
    this.refresh();
  }

  /** While a job runs, neither new variations nor keeping one. */
  setBusy(busy) {
    this.busy = busy;
    this.refresh();
  }

  refresh() {
    this.button.disabled = this.busy || !this.available;
    for (const cell of this.cells) cell.keepButton.disabled = this.busy || !cell.snapshot;
  }

  /**
   * Run the variations ``jobs`` of the operation ``op`` ([{seed, options, body, texture}]) at
   * once, each through ``submit(body, {report, onJob})`` (app.js's submitJob: resolves to the
   * job's final status document, null when it was cancelled), its result then fetched with
   * ``key`` under the service's name. ``progress(fraction)`` is told the mean progress.
   *
   * Resolves to the line for the page's status ("done: 4 variations", "cancelled", ...);
   * throws the first problem when none came to an end but failures.
   */
  async run(op, jobs, { submit, key, signal, progress }) {
    for (const url of this.urls.splice(0)) URL.revokeObjectURL(url);
    this.op = op;
    this.key = key;
    this.cells = jobs.map((job) => new Cell(job, (cell) => this.choose(cell)));
    this.grid.replaceChildren(...this.cells.map((cell) => cell.element));
    this.section.hidden = false;
    this.refresh();
    const moved = () => progress(this.cells.reduce((sum, cell) => sum + cell.fraction, 0) /
      this.cells.length);
    const outcomes = await Promise.allSettled(this.cells.map(async (cell) => {
      const snapshot = await submit(cell.job.body, {
        report: (data) => {
          cell.report(data);
          moved();
        },
        onJob: (id) => cell.setJob(id),
      });
      if (!snapshot) throw new DOMException("cancelled", "AbortError");
      cell.setStatus("fetching", "fetching the result");
      const id = snapshot.id || cell.id;
      const file = await getFile(snapshot.result || `/jobs/${id}/result`,
        `quilting-${id}.png`, { key, signal });
      const url = URL.createObjectURL(file.blob);
      this.urls.push(url);
      cell.finish(snapshot, file, url);
      moved();
    }));
    const failures = [];
    outcomes.forEach((outcome, i) => {
      if (outcome.status === "fulfilled") return;
      const cancelled = outcome.reason?.name === "AbortError";
      if (!cancelled) failures.push(outcome.reason);
      this.cells[i].end(cancelled ? "cancelled" : "failed",
        cancelled ? "cancelled" : problemWords(outcome.reason));
    });
    moved();
    this.refresh();
    const done = this.cells.filter((cell) => cell.snapshot).length;
    const cancelled = outcomes.length - done - failures.length;
    if (!done && failures.length && !cancelled) throw failures[0];
    const counts = [`${done} of ${jobs.length} variations done`];
    if (failures.length) counts.push(`${failures.length} failed`);
    if (cancelled) return `cancelled (${counts.join(", ")})`;
    return failures.length ? `done: ${counts.join(", ")}` : `done: ${jobs.length} variations`;
  }

  /** "Keep this one": the cell marked, and the variation handed to the page. */
  choose(cell) {
    for (const other of this.cells) {
      other.element.classList.toggle("kept", other === cell);
      if (other === cell) other.element.setAttribute("aria-current", "true");
      else other.element.removeAttribute("aria-current");
    }
    this.keep({
      op: this.op, key: this.key, seed: cell.job.seed, options: cell.job.options,
      body: cell.job.body, texture: cell.job.texture, snapshot: cell.snapshot,
    });
  }
}
