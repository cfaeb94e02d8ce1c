// A brush over an image: one label per image pixel (the image's natural size, whatever size it
// is shown at), set with a round hard-edged brush along the pointer's path, shown on a canvas
// over the picture, undone a stroke at a time, and sent as a PNG of the image's size. The
// fill's mask (mask.js: painted or not) and the alpha's scribbles (alpha.js: keep, remove or
// unknown) are two of them; each says what its labels look like, mean and are sent as.

const $ = (id) => document.getElementById(id);

/** Strokes kept for Undo. */
const UNDO_DEPTH = 20;
/** The most an image is enlarged to be painted on, and the share of the window's height it
 * may take. */
const MAX_ENLARGE = 4;
const MAX_HEIGHT = 0.6;

/**
 * Set to ``value`` every pixel of ``labels`` (``width`` x ``height``, row by row) whose centre
 * is within ``radius`` of the segment from ``a`` to ``b`` (image pixels, fractional): a
 * hard-edged stroke, so what is sent is exactly what is shown. ``changed(was)`` is called for
 * each pixel that held another value. Returns the box it may have changed ``{x, y, w, h}``,
 * or null when the segment lies outside the image.
 */
export function stamp(labels, width, height, a, b, radius, value, changed) {
  const x0 = Math.max(0, Math.floor(Math.min(a.x, b.x) - radius));
  const y0 = Math.max(0, Math.floor(Math.min(a.y, b.y) - radius));
  const x1 = Math.min(width, Math.ceil(Math.max(a.x, b.x) + radius));
  const y1 = Math.min(height, Math.ceil(Math.max(a.y, b.y) + radius));
  if (x1 <= x0 || y1 <= y0) return null;
  const dx = b.x - a.x;
  const dy = b.y - a.y;
  const length2 = dx * dx + dy * dy;
  const r2 = radius * radius;
  for (let y = y0; y < y1; y += 1) {
    for (let x = x0; x < x1; x += 1) {
      const px = x + 0.5 - a.x;
      const py = y + 0.5 - a.y;
      const t = length2 ? Math.min(1, Math.max(0, (px * dx + py * dy) / length2)) : 0;
      const ex = px - t * dx;
      const ey = py - t * dy;
      if (ex * ex + ey * ey > r2) continue;
      const i = y * width + x;
      if (labels[i] !== value) {
        changed(labels[i]);
        labels[i] = value;
      }
    }
  }
  return { x: x0, y: y0, w: x1 - x0, h: y1 - y0 };
}

/** The smallest box holding the boxes ``a`` and ``b``. */
export function union(a, b) {
  const x = Math.min(a.x, b.x);
  const y = Math.min(a.y, b.y);
  return { x, y, w: Math.max(a.x + a.w, b.x + b.w) - x, h: Math.max(a.y + a.h, b.y + b.h) - y };
}

/**
 * The painting shared by every brush of the page. A subclass gives the brush's label
 * (``brush``), says what changed (``changed(problem)``), and may note a stroke (``stroked()``).
 *
 * ``ids`` names the elements: ``editor`` (holds the picture and the canvas), ``image``,
 * ``canvas``, ``cursor``, ``size`` (the brush's range input), ``sizeValue`` (its output),
 * ``undo``, ``clear`` and ``room`` (the panel whose width the picture fits). ``overlay`` is the
 * RGBA of each label on the canvas (label 0 is never drawn); ``kinds`` how many labels there
 * are.
 */
export class Painter {
  constructor(ids, overlay, kinds) {
    this.ids = ids;
    this.overlay = overlay;
    this.width = 0;
    this.height = 0;
    this.labels = null; // Uint8Array, one label per image pixel, row by row
    this.counts = new Array(kinds).fill(0); // pixels of each label
    this.undo = []; // [{x, y, w, h, pixels}]: what a stroke changed, as it was before
    this.stroke = null; // {before, last, box} while the pointer is down
    this.imageUrl = null;

    this.editor = $(ids.editor);
    this.image = $(ids.image);
    this.canvas = $(ids.canvas);
    this.cursor = $(ids.cursor);
    this.size = $(ids.size);
    this.context = this.canvas.getContext("2d");

    this.canvas.addEventListener("pointerdown", (event) => this.down(event));
    this.canvas.addEventListener("pointermove", (event) => this.move(event));
    this.canvas.addEventListener("pointerup", (event) => this.up(event));
    this.canvas.addEventListener("pointercancel", (event) => this.up(event));
    this.canvas.addEventListener("pointerleave", () => { this.cursor.hidden = true; });
    this.size.addEventListener("input", () => this.showSize());
    $(ids.undo).addEventListener("click", () => this.undoStroke());
    $(ids.clear).addEventListener("click", () => this.clear());
    new ResizeObserver(() => this.fit()).observe($(ids.room));
  }

  /** Pixels holding a label other than 0 (painted). */
  get painted() {
    return this.labels ? this.labels.length - this.counts[0] : 0;
  }

  /** Nothing shown: no image, no labels. */
  forget() {
    if (this.imageUrl) URL.revokeObjectURL(this.imageUrl);
    this.imageUrl = null;
    this.width = this.height = 0;
    this.labels = null;
    this.editor.hidden = true;
  }

  /** Show ``file`` to paint on; resolves to whether it could be decoded here. */
  async show(file) {
    this.imageUrl = URL.createObjectURL(file);
    this.image.src = this.imageUrl;
    try {
      await this.image.decode();
      return true;
    } catch {
      return false;
    }
  }

  /** Start painting on the decoded image: every label 0, the brush ``1 / share`` of its
   * shorter side. */
  start(share) {
    this.width = this.image.naturalWidth;
    this.height = this.image.naturalHeight;
    this.canvas.width = this.width;
    this.canvas.height = this.height;
    this.labels = new Uint8Array(this.width * this.height);
    const shorter = Math.min(this.width, this.height);
    this.size.max = String(Math.max(4, Math.round(shorter / 2)));
    this.size.value = String(Math.max(1, Math.round(shorter / share)));
    this.showSize();
    this.editor.hidden = false;
    this.fit();
  }

  /** Forget the strokes: the labels as they now are become the start. */
  recount() {
    this.undo = [];
    this.counts.fill(0);
    for (const label of this.labels || []) this.counts[label] += 1;
    this.context.clearRect(0, 0, this.width, this.height);
    this.redraw(0, 0, this.width, this.height);
  }

  clear() {
    if (!this.labels || !this.painted) return;
    this.remember({ x: 0, y: 0, w: this.width, h: this.height }, this.labels.slice());
    this.labels.fill(0);
    this.counts.fill(0);
    this.counts[0] = this.labels.length;
    this.context.clearRect(0, 0, this.width, this.height);
    this.stroked();
    this.changed();
  }

  /** A stroke, an undo or a clear changed the labels (a subclass may note it). */
  stroked() {}

  // --- showing it ------------------------------------------------------------------------------

  /** Size the picture to its panel: as large as fits, at most MAX_ENLARGE times. */
  fit() {
    if (!this.width) return;
    const room = $(this.ids.room).clientWidth;
    if (!room) return; // hidden (another operation): fitted when shown
    const tall = window.innerHeight * MAX_HEIGHT;
    const scale = Math.min(MAX_ENLARGE, room / this.width, tall / this.height);
    for (const element of [this.image, this.canvas]) {
      element.style.width = `${this.width * scale}px`;
      element.style.height = `${this.height * scale}px`;
    }
    this.editor.classList.toggle("pixelated", scale >= 2);
  }

  showSize() {
    $(this.ids.sizeValue).textContent = `${this.size.value} px`;
  }

  /** The overlay's pixels in the box, from the labels. */
  redraw(x, y, w, h) {
    if (!this.labels || w <= 0 || h <= 0) return;
    const pixels = this.context.createImageData(w, h);
    const data = pixels.data;
    for (let row = 0; row < h; row += 1) {
      const from = (y + row) * this.width + x;
      for (let col = 0; col < w; col += 1) {
        const label = this.labels[from + col];
        if (label) data.set(this.overlay[label], 4 * (row * w + col));
      }
    }
    this.context.putImageData(pixels, x, y);
  }

  // --- painting --------------------------------------------------------------------------------

  /** The pointer's position in image pixels (fractional), from where it is on the screen. */
  at(event) {
    const box = this.canvas.getBoundingClientRect();
    return {
      x: (event.clientX - box.left) * this.width / box.width,
      y: (event.clientY - box.top) * this.height / box.height,
    };
  }

  down(event) {
    if (!this.labels || event.button !== 0) return;
    event.preventDefault();
    this.canvas.setPointerCapture(event.pointerId);
    const point = this.at(event);
    this.stroke = { before: this.labels.slice(), last: point, box: null };
    this.paint(point, point);
  }

  move(event) {
    this.showCursor(event);
    if (!this.stroke) return;
    const point = this.at(event);
    this.paint(this.stroke.last, point);
    this.stroke.last = point;
  }

  up(event) {
    if (!this.stroke) return;
    if (this.canvas.hasPointerCapture(event.pointerId)) {
      this.canvas.releasePointerCapture(event.pointerId);
    }
    const { before, box } = this.stroke;
    this.stroke = null;
    if (box) this.remember(box, before);
    this.stroked();
    this.changed();
  }

  showCursor(event) {
    const box = this.canvas.getBoundingClientRect();
    const side = Number(this.size.value) * box.width / this.width;
    const style = this.cursor.style;
    style.width = style.height = `${side}px`;
    style.left = `${event.clientX - box.left - side / 2}px`;
    style.top = `${event.clientY - box.top - side / 2}px`;
    this.cursor.hidden = false;
  }

  /** Set the segment from ``a`` to ``b`` to the brush's label (see :func:`stamp`). */
  paint(a, b) {
    const radius = Math.max(0.5, Number(this.size.value) / 2);
    const value = this.brush;
    const drawn = stamp(this.labels, this.width, this.height, a, b, radius, value, (was) => {
      this.counts[was] -= 1;
      this.counts[value] += 1;
    });
    if (!drawn) return;
    const box = this.stroke.box;
    this.stroke.box = box ? union(box, drawn) : drawn;
    this.context.clearRect(drawn.x, drawn.y, drawn.w, drawn.h);
    this.redraw(drawn.x, drawn.y, drawn.w, drawn.h);
    this.changed();
  }

  /** Keep the box of ``before`` (all the labels as they were) for Undo. */
  remember(box, before) {
    const pixels = new Uint8Array(box.w * box.h);
    for (let row = 0; row < box.h; row += 1) {
      const from = (box.y + row) * this.width + box.x;
      pixels.set(before.subarray(from, from + box.w), row * box.w);
    }
    this.undo.push({ ...box, pixels });
    if (this.undo.length > UNDO_DEPTH) this.undo.shift();
  }

  undoStroke() {
    const step = this.undo.pop();
    if (!step) return;
    const { x, y, w, h, pixels } = step;
    for (let row = 0; row < h; row += 1) {
      const at = (y + row) * this.width + x;
      const now = this.labels.subarray(at, at + w);
      for (let col = 0; col < w; col += 1) {
        this.counts[now[col]] -= 1;
        this.counts[pixels[row * w + col]] += 1;
      }
      now.set(pixels.subarray(row * w, (row + 1) * w));
    }
    this.context.clearRect(x, y, w, h);
    this.redraw(x, y, w, h);
    this.stroked();
    this.changed();
  }

  // --- sending it ------------------------------------------------------------------------------

  /** The labels as a PNG of the image's natural size, each label the RGBA ``sent[label]``
   * (transparent where it has none); ``what`` names it in an error. */
  async png(sent, what) {
    const canvas = document.createElement("canvas");
    canvas.width = this.width;
    canvas.height = this.height;
    const context = canvas.getContext("2d");
    const pixels = context.createImageData(this.width, this.height);
    const data = pixels.data;
    for (let i = 0; i < this.labels.length; i += 1) {
      const colour = sent[this.labels[i]];
      if (colour) data.set(colour, 4 * i);
    }
    context.putImageData(pixels, 0, 0);
    return new Promise((resolve, reject) => canvas.toBlob(
      (blob) => (blob ? resolve(blob) : reject(new Error(`${what} could not be made`))),
      "image/png"));
  }
}
