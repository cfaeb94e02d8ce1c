// Alpha from an ordinary photo: an opaque texture (ice, smoke, leaves shot against a
// background) comes with what the artist says of it, a trimap file or scribbles painted over
// it, white what to keep and black what to remove. "Extract alpha" shows the RGBA texture the
// service makes of it (POST /extract-alpha); a synthesis sends the same parts beside the
// texture, so that the alpha is extracted first and then quilted (alpha quilting).

import { Painter } from "./painter.js";

const $ = (id) => document.getElementById(id);

/** What a scribble pixel holds: nothing (unknown), a keep (white) or a remove (black) stroke. */
const NONE = 0;
const KEEP = 1;
const REMOVE = 2;
/** How each is shown and sent: white and black, opaque; the rest transparent (unknown). */
const SENT = { [KEEP]: [255, 255, 255, 255], [REMOVE]: [0, 0, 0, 255] };
/** The methods and foreground estimates offered when the service's schemas name none (they
 * could not be loaded). */
const METHODS = ["lkm", "cf", "knn"];
const FOREGROUNDS = ["ml", "photo"];

/** The start of the PNG signature; a JPEG's first bytes. */
const PNG = [0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a];
const JPEG = [0xff, 0xd8, 0xff];
/** How far into a PNG its chunks are read for a tRNS before the pixels (IDAT) start. */
const HEAD_BYTES = 1 << 16;

/**
 * Whether an image file has an alpha channel as the service reads it: "alpha" (a PNG of gray
 * or colour with alpha, or with a tRNS transparency), "opaque" (any other PNG, a JPEG), or
 * "unknown" (another format, or unreadable here: the service decides).
 */
export async function alphaOf(file) {
  let bytes;
  try {
    bytes = new Uint8Array(await file.slice(0, HEAD_BYTES).arrayBuffer());
  } catch {
    return "unknown";
  }
  const starts = (sign) => sign.every((byte, i) => bytes[i] === byte);
  if (starts(JPEG)) return "opaque";
  if (!starts(PNG) || bytes.length < 33) return "unknown";
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const type = (at) => String.fromCharCode(...bytes.subarray(at + 4, at + 8));
  if (type(8) !== "IHDR") return "unknown";
  const colour = bytes[25];
  if (colour === 4 || colour === 6) return "alpha"; // gray + alpha, RGBA
  for (let at = 8; at + 8 <= bytes.length; at += 12 + view.getUint32(at)) {
    const chunk = type(at);
    if (chunk === "tRNS") return "alpha"; // a palette's or a colour key's transparency
    if (chunk === "IDAT" || chunk === "IEND") return "opaque";
  }
  return "unknown"; // the header chunks run past what was read: let the service say
}

/**
 * The extractions a result says were made: its ``Quilting-Extracted`` header (compact JSON,
 * an array of one entry per photo, null for a photo without a trimap or scribbles) or the
 * same array from the job's ``stats.extracted``. Returns ``[{index, summary}]``, one per photo
 * whose alpha was extracted (``index``: the photo's place, from 0), each ``summary``
 * ``{method, foreground, unknown, iterations, seconds}``; empty when there is none (no
 * header, or one this page cannot read).
 */
export function summariesOf(value) {
  let found = value;
  if (typeof value === "string") {
    try {
      found = JSON.parse(value);
    } catch {
      return [];
    }
  }
  if (found && typeof found === "object" && !Array.isArray(found)) found = [found];
  if (!Array.isArray(found)) return [];
  return found
    .map((summary, index) => ({ index, summary }))
    .filter(({ summary }) => summary && typeof summary === "object");
}

/** "the photo", or for one of several photos "texture 2" (``noun``: "texture", "layer"). */
function whose(entry, several, noun) {
  return several ? `${noun} ${entry.index + 1}` : "the photo";
}

/**
 * The extractions as the result's figures, ``[[label, text]]``: the method, the foreground
 * estimate, the share of the photo solved for, the iterations and the time; each label
 * followed by its photo ("matting (layer 2)") when several photos were extracted, or when
 * ``count`` (the photos sent) is more than one.
 */
export function summaryStats(entries, { noun = "texture", count = 1 } = {}) {
  const several = entries.length > 1 || count > 1;
  const stats = [];
  for (const entry of entries) {
    const { summary } = entry;
    const of = several ? ` (${whose(entry, true, noun)})` : "";
    if (summary.method) stats.push([`matting${of}`, String(summary.method)]);
    if (summary.foreground) stats.push([`foreground${of}`, String(summary.foreground)]);
    if (typeof summary.unknown === "number") {
      stats.push([`unknown${of}`, `${(100 * summary.unknown).toFixed(1)} % of the photo`]);
    }
    if (Number.isInteger(summary.iterations)) {
      stats.push([`iterations${of}`, String(summary.iterations)]);
    }
    if (typeof summary.seconds === "number") {
      stats.push([`extraction time${of}`, `${summary.seconds.toFixed(2)} s`]);
    }
  }
  return stats;
}

/**
 * The extractions in words, one line each: "Extracted with knn (foreground ml): 38.2 % of
 * the photo solved for, in 84 iterations, 0.41 s." (for one of several photos, "Layer 2:
 * extracted with ..."); "" when there is none.
 */
export function summaryLine(entries, { noun = "texture", count = 1 } = {}) {
  const several = entries.length > 1 || count > 1;
  return entries.map((entry) => {
    const { summary } = entry;
    const how = summary.foreground ? ` (foreground ${summary.foreground})` : "";
    const figures = [];
    if (typeof summary.unknown === "number") {
      figures.push(`${(100 * summary.unknown).toFixed(1)} % of the photo solved for`);
    }
    if (Number.isInteger(summary.iterations)) {
      figures.push(`in ${summary.iterations} iteration${summary.iterations === 1 ? "" : "s"}`);
    }
    if (typeof summary.seconds === "number") figures.push(`${summary.seconds.toFixed(2)} s`);
    const line = `extracted with ${summary.method || "the service's method"}${how}` +
      (figures.length ? `: ${figures.join(", ")}.` : ".");
    if (!several) return line.charAt(0).toUpperCase() + line.slice(1);
    const who = whose(entry, true, noun);
    return `${who.charAt(0).toUpperCase()}${who.slice(1)}: ${line}`;
  }).join("\n");
}

/** A client-side refusal, with the control to fix (focused when shown). */
function refusal(input, message) {
  const error = new Error(message);
  error.input = input;
  return error;
}

/**
 * Scribbles painted over the photo: one label per photo pixel (the photo's natural size,
 * whatever size it is shown at), a white "keep" brush, a black "remove" brush and an eraser,
 * each a round hard-edged brush; sent as a PNG of the photo's size, white and black where
 * painted, transparent (unknown) elsewhere.
 */
export class ScribblePainter extends Painter {
  constructor() {
    super(
      {
        editor: "scribble-editor",
        image: "scribble-image",
        canvas: "scribble-canvas",
        cursor: "scribble-cursor",
        size: "scribble-size",
        sizeValue: "scribble-size-value",
        undo: "scribble-undo",
        clear: "scribble-clear",
        room: "alpha",
      },
      SENT,
      3,
    );
    this.loads = 0; // so that only the latest photo is shown
    this.onChange = () => {};
  }

  /** The brush's label: KEEP, REMOVE, or NONE for the eraser. */
  get brush() {
    const value = document.querySelector('input[name="scribble"]:checked').value;
    return { keep: KEEP, remove: REMOVE }[value] ?? NONE;
  }

  /** True when nothing is painted (or there is no photo). */
  get empty() {
    return this.counts[KEEP] + this.counts[REMOVE] === 0;
  }

  /** Painted pixels: ``{keep, remove}``. */
  get strokes() {
    return { keep: this.counts[KEEP], remove: this.counts[REMOVE] };
  }

  /** Paint on ``file`` (null: none); the scribbles start empty. */
  async setImage(file) {
    const load = ++this.loads;
    this.forget();
    let problem = null;
    if (file) {
      const shown = await this.show(file);
      if (load !== this.loads) return;
      if (shown) this.start(16);
      else problem = "This photo cannot be shown here: give a trimap file instead.";
    }
    this.recount();
    this.changed(problem);
  }

  changed(problem = null) {
    const info = $("scribble-info");
    const { keep, remove } = this.strokes;
    if (problem) info.textContent = problem;
    else if (!this.labels) info.textContent = "Choose an opaque photo as the texture to paint on it.";
    else if (!keep && !remove) {
      info.textContent = "Nothing painted: white over some of what to keep, black over some " +
        "of the background.";
    } else {
      info.textContent = `${keep} pixels to keep, ${remove} to remove`;
    }
    $("scribble-undo").disabled = !this.undo.length;
    $("scribble-clear").disabled = this.empty;
    this.onChange();
  }

  /** The scribbles as a PNG of the photo's natural size: white kept, black removed, the rest
   * transparent (unknown). */
  png() {
    return super.png(SENT, "the scribbles");
  }
}

/** A choice's values and default from a schema property (unwrapping ``anyOf [x, null]``). */
function choiceOf(prop) {
  const spec = (prop?.anyOf || []).find((variant) => variant.enum) || prop || {};
  return {
    values: Array.isArray(spec.enum) ? spec.enum : [],
    default: spec.default ?? prop?.default,
    description: spec.description || prop?.description || "",
  };
}

/** Fill ``select`` with ``values``, keeping its value where it still is one, else
 * ``fallback`` (or the first). */
function fillMenu(select, values, fallback) {
  const previous = select.value;
  select.replaceChildren(...values.map((value) => new Option(value, value)));
  select.value = values.includes(previous) ? previous
    : values.includes(fallback) ? fallback : values[0];
}

/**
 * The panel: the photo's alpha (has it one?), the trimap file, the scribbles, the matting
 * method and the foreground estimate, and the parts a request sends of them. It is folded
 * (``#alpha-details``, closed on load) until opened, and opens by itself when a trimap is
 * chosen; it never folds itself up. Its summary says what it holds while folded (all of it is
 * sent) and when the texture has an alpha of its own (the panel is then not needed).
 */
export class AlphaPanel {
  /** ``onMethod(value)``: the method menu changed (the page keeps ``matting`` the same). */
  constructor({ onMethod = () => {} } = {}) {
    this.painter = new ScribblePainter();
    this.painter.onChange = () => this.describe();
    this.details = $("alpha-details");
    this.trimap = $("trimap");
    this.method = $("alpha-method");
    this.foreground = $("alpha-foreground");
    this.defaults = {}; // AlphaOptions' defaults: what the extraction need not send
    this.photo = null; // the texture the panel is about (the first chosen)
    this.several = false; // more than one texture chosen
    this.kind = "unknown"; // alphaOf(photo)
    this.photoSize = null; // [width, height], or null
    this.trimapSize = null;
    // Only the latest photo's (and trimap's) reads are shown.
    this.photoReads = 0;
    this.trimapReads = 0;
    $("trimap-info").dataset.empty = $("trimap-info").textContent;
    this.trimap.addEventListener("change", () => {
      // Chosen (or dropped, or pasted) here: shown open, so that what is sent can be seen.
      if (this.trimap.files[0]) this.details.open = true;
      this.readTrimap();
    });
    this.details.addEventListener("toggle", () => this.describeFolded());
    this.method.addEventListener("change", () => onMethod(this.method.value));
    // The menus are filled by setSchemas, once the page has read the service's schemas.
  }

  /**
   * The menus from the service's schemas: the method's choices, default and description from
   * the synthesis's ``matting`` (the same menu sets both), else the extraction's
   * ``AlphaOptions.method``; the foreground's from ``AlphaOptions.foreground``. The built-in
   * lists when the schemas name none (they could not be loaded).
   */
  setSchemas(schemas) {
    const options = schemas?.AlphaOptions?.properties || {};
    const matting = choiceOf(schemas?.SynthesizeOptions?.properties?.matting);
    const method = matting.values.length ? matting : choiceOf(options.method);
    const foreground = choiceOf(options.foreground);
    const methods = method.values.length ? method.values : METHODS;
    const foregrounds = foreground.values.length ? foreground.values : FOREGROUNDS;
    fillMenu(this.method, methods, method.default);
    fillMenu(this.foreground, foregrounds, foreground.default);
    // What the service does when not told: not sent (unknown without a schema: all sent).
    this.defaults = {
      method: choiceOf(options.method).default ?? method.default,
      foreground: foreground.default,
    };
    for (const [id, text] of [["alpha-method-hint", method.description],
      ["alpha-foreground-hint", foreground.description &&
        `Extract alpha only (a synthesis estimates it): ${foreground.description}`]]) {
      if (!text) continue;
      $(id).textContent = text; // one line (style.css); the whole read out and as tooltip
      $(id).title = text;
    }
  }

  /** Set the method menu (from the ``matting`` option); false for a value it does not have. */
  setMethod(value) {
    if (![...this.method.options].some((option) => option.value === value)) return false;
    this.method.value = value;
    return true;
  }

  /** The textures chosen: the panel is about the first; scribbles start afresh on a new one. */
  async setTextures(files) {
    const file = files[0] || null;
    this.several = files.length > 1;
    if (file === this.photo) {
      this.describe();
      return;
    }
    this.photo = file;
    const read = ++this.photoReads;
    this.kind = "unknown";
    this.photoSize = null;
    const [kind, size] = await Promise.all([
      file ? alphaOf(file) : "unknown",
      file ? bitmapSize(file) : null,
      this.painter.setImage(file),
    ]);
    if (read !== this.photoReads) return;
    this.kind = kind;
    this.photoSize = size;
    if (kind === "alpha") this.painter.editor.hidden = true; // nothing to paint for
    this.describe();
    this.describeTrimap();
  }

  async readTrimap() {
    const file = this.trimap.files[0];
    const read = ++this.trimapReads;
    const size = file ? await bitmapSize(file) : null;
    if (read !== this.trimapReads) return;
    this.trimapSize = size;
    this.describeTrimap();
    this.describe();
  }

  /** The trimap box's hint: the file's size, and a word where it is not the photo's. */
  describeTrimap() {
    const info = $("trimap-info");
    const file = this.trimap.files[0];
    if (!file) {
      info.textContent = info.dataset.empty;
      return;
    }
    const size = this.trimapSize;
    let text = size ? `${file.name}: ${size[0]} × ${size[1]} pixels`
      : `${file.name}: not an image this browser can show`;
    const photo = this.photoSize;
    if (size && photo && (size[0] !== photo[0] || size[1] !== photo[1])) {
      text += `, not the photo's ${photo[0]} × ${photo[1]}`;
    }
    info.textContent = text;
  }

  /** The panel's line: what the photo is and what is given for its alpha. */
  describe() {
    const info = $("alpha-info");
    if (!this.photo) {
      info.textContent = "Choose a texture first: an opaque photo, without alpha.";
    } else if (this.kind === "alpha") {
      info.textContent = `${this.photo.name} has an alpha channel of its own: it is quilted ` +
        "as it is (no trimap or scribbles needed).";
    } else {
      const first = this.several ? " (the first texture; the others are sent as they are)"
        : "";
      info.textContent = this.given
        ? `The alpha of ${this.photo.name}${first} is extracted from the ` +
          `${this.sources.join(" and ")}, then quilted.`
        : `${this.photo.name}${first} is opaque: give a trimap or paint scribbles to ` +
          "extract its alpha.";
    }
    this.describeFolded();
  }

  /**
   * The summary's state after its title: "not needed, sky.png has alpha of its own" for a
   * texture with alpha; while folded, what the panel holds and a request sends ("trimap
   * mask.png", "scribbles (454 px to keep, 502 to remove)"); nothing else.
   */
  describeFolded() {
    const said = [];
    if (this.photo && this.kind === "alpha") {
      said.push(`not needed, ${this.photo.name} has alpha of its own`);
    }
    if (!this.details.open) {
      const held = [];
      const file = this.trimap.files[0];
      if (file) held.push(`trimap ${file.name}`);
      if (!this.painter.empty) {
        const { keep, remove } = this.painter.strokes;
        held.push(`scribbles (${keep} px to keep, ${remove} to remove)`);
      }
      if (held.length) said.push(held.join(" and "));
    }
    $("alpha-state").textContent = said.length ? `: ${said.join("; ")}` : "";
  }

  /** Show what the service says it extracted (``summaryLine``'s text; "" keeps the line). */
  showSummary(text) {
    if (text) $("alpha-info").textContent = text;
  }

  /** Whether a trimap or scribbles are given. */
  get given() {
    return this.sources.length > 0;
  }

  /** What is given: ["trimap", "scribbles"], either or none. */
  get sources() {
    const sources = [];
    if (this.trimap.files[0]) sources.push("trimap");
    if (!this.painter.empty) sources.push("scribbles");
    return sources;
  }

  /**
   * The alpha parts of a synthesis of ``count`` textures, ``[[name, blob-or-promise,
   * filename]]``: the trimap file as it is and the scribbles as a PNG, both of the first
   * texture, each followed by an empty part for every other texture (the service takes none
   * or one per texture, in their order). Empty when none is given; throws (with the control
   * to fix) for a photo that has alpha already.
   */
  parts(count = 1) {
    if (!this.given) return [];
    const parts = [];
    for (const [name, blob, filename] of this.alphaParts()) {
      parts.push([name, blob, filename]);
      for (let i = 1; i < count; i += 1) parts.push([name, new Blob([]), "none"]);
    }
    return parts;
  }

  alphaParts() {
    if (this.kind === "alpha") {
      throw refusal(this.trimap.files[0] ? this.trimap : $("scribble-clear"),
        `${this.photo.name} has an alpha channel already: it needs no trimap or scribbles ` +
        "(remove the trimap, clear the scribbles), or choose an opaque photo");
    }
    const parts = [];
    const file = this.trimap.files[0];
    if (file) parts.push(["trimap", file, file.name]);
    if (!this.painter.empty) parts.push(["scribbles", this.painter.png(), "scribbles.png"]);
    return parts;
  }

  /** The extraction's options: the method and foreground chosen, those that are not the
   * service's defaults (all of them when its schema could not be read). */
  extractOptions() {
    const options = {};
    for (const [name, select] of [["method", this.method], ["foreground", this.foreground]]) {
      if (select.value && select.value !== this.defaults[name]) options[name] = select.value;
    }
    return options;
  }

  /**
   * The body of ``POST /extract-alpha`` (a promise: the scribbles are encoded first) and the
   * photo; throws, with the control to fix, on what is missing.
   */
  extractRequest() {
    const photo = this.photo;
    if (!photo) throw refusal($("texture"), "choose a texture first: an opaque photo");
    if (this.kind === "alpha") {
      throw refusal($("texture"), `${photo.name} has an alpha channel already: there is ` +
        "nothing to extract (choose an opaque photo)");
    }
    if (!this.given) {
      throw refusal(this.trimap, "give a trimap, or paint scribbles on the photo: white " +
        "over some of what to keep, black over some of the background");
    }
    const parts = this.alphaParts();
    const options = this.extractOptions();
    const body = Promise.all(parts.map(([, blob]) => blob)).then((blobs) => {
      const form = new FormData();
      form.append("photo", photo);
      parts.forEach(([name, , filename], i) => form.append(name, blobs[i], filename));
      form.append("options", JSON.stringify(options));
      return form;
    });
    return { body, photo };
  }
}

/** [width, height] of an image file, or null where this browser cannot decode it. */
async function bitmapSize(file) {
  try {
    const bitmap = await createImageBitmap(file);
    const size = [bitmap.width, bitmap.height];
    bitmap.close();
    return size;
  } catch {
    return null;
  }
}
