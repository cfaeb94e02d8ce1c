// The mask of a fill, painted on the image: a canvas over the picture, one mask pixel per image
// pixel (the image's natural size, whatever size it is shown at), painted and erased with a
// round brush, shown half-transparent, and sent as a PNG: white where painted, black elsewhere.

const $ = (id) => document.getElementById(id);

/** The painted area's colour on the overlay (the overlay itself is half-transparent). */
const PAINT = [255, 0, 110, 255];
/** Strokes kept for Undo. */
const UNDO_DEPTH = 20;
/** The most an image is enlarged to be painted on, and the share of the window's height it
 * may take. */
const MAX_ENLARGE = 4;
const MAX_HEIGHT = 0.6;

function decoded(file) {
  // The file's own values: no colour management, no premultiplication (a mask is data).
  return createImageBitmap(file, { colorSpaceConversion: "none", premultiplyAlpha: "none" });
}

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

export class MaskPainter {
  constructor() {
    this.width = 0;
    this.height = 0;
    this.mask = null; // Uint8Array, 1 where painted, row by row
    this.count = 0; // painted pixels
    this.edited = false; // changed since the mask file was loaded (or painted from nothing)
    this.undo = []; // [{x, y, w, h, pixels}]: what a stroke changed, as it was before
    this.stroke = null; // {before, last, box} while the pointer is down
    this.imageUrl = null;
    this.ready = Promise.resolve(); // the latest image, once shown
    this.imageLoads = 0; // so that only the latest image and mask file are shown
    this.maskLoads = 0;

    this.editor = $("mask-editor");
    this.image = $("mask-image");
    this.canvas = $("mask-canvas");
    this.cursor = $("brush-cursor");
    this.size = $("brush-size");
    this.context = this.canvas.getContext("2d");

    this.canvas.addEventListener("pointerdown", (event) => this.down(event));
    this.canvas.addEventListener("pointermove", (event) => this.move(event));
    this.canvas.addEventListener("pointerup", (event) => this.up(event));
    this.canvas.addEventListener("pointercancel", (event) => this.up(event));
    this.canvas.addEventListener("pointerleave", () => { this.cursor.hidden = true; });
    this.size.addEventListener("input", () => this.showSize());
    $("mask-undo").addEventListener("click", () => this.undoStroke());
    $("mask-clear").addEventListener("click", () => this.clear());
    new ResizeObserver(() => this.fit()).observe($("painter"));
  }

  get erasing() {
    return document.querySelector('input[name="brush"]:checked').value === "erase";
  }

  /** True when the image is loaded and nothing is painted. */
  get empty() {
    return this.count === 0;
  }

  // --- the image and a mask file ---------------------------------------------------------------

  /** Paint on ``file`` (null: no image); the painted mask starts empty. */
  setImage(file) {
    this.ready = this.showImage(file, ++this.imageLoads);
    return this.ready;
  }

  async showImage(file, load) {
    if (this.imageUrl) URL.revokeObjectURL(this.imageUrl);
    this.imageUrl = null;
    this.width = this.height = 0;
    this.mask = null;
    this.editor.hidden = true;
    if (file) {
      this.imageUrl = URL.createObjectURL(file);
      this.image.src = this.imageUrl;
      try {
        await this.image.decode();
      } catch {
        if (load === this.imageLoads) this.changed("This image cannot be shown here.");
        return;
      }
      if (load !== this.imageLoads) return;
      this.width = this.image.naturalWidth;
      this.height = this.image.naturalHeight;
      this.canvas.width = this.width;
      this.canvas.height = this.height;
      this.mask = new Uint8Array(this.width * this.height);
      const shorter = Math.min(this.width, this.height);
      this.size.max = String(Math.max(4, Math.round(shorter / 2)));
      this.size.value = String(Math.max(1, Math.round(shorter / 12)));
      this.showSize();
      this.editor.hidden = false;
      this.fit();
    }
    this.reset(false);
  }

  /**
   * Show a mask file as the painted area, to be painted on further: a pixel of any non-zero
   * colour is painted, one of alpha 0 is not (as the service reads it). Resolves to why it
   * is not shown (not the image's size, not readable here), or null once it is.
   */
  async loadMask(file) {
    const load = ++this.maskLoads;
    this.edited = false; // the file is what is sent, until it is painted on
    await this.ready;
    const image = this.imageLoads;
    const current = () => load === this.maskLoads && image === this.imageLoads;
    if (!this.mask) return "sent as it is (there is no image here to show it on)";
    let bitmap;
    try {
      bitmap = await decoded(file);
    } catch {
      return "not readable here; it is sent as it is";
    }
    if (!current()) {
      bitmap.close();
      return null;
    }
    if (bitmap.width !== this.width || bitmap.height !== this.height) {
      const size = `${bitmap.width} × ${bitmap.height}`;
      bitmap.close();
      return `${size}, not the image's ${this.width} × ${this.height}`;
    }
    const scratch = document.createElement("canvas");
    scratch.width = this.width;
    scratch.height = this.height;
    const context = scratch.getContext("2d", { willReadFrequently: true });
    context.drawImage(bitmap, 0, 0);
    bitmap.close();
    const rgba = context.getImageData(0, 0, this.width, this.height).data;
    for (let i = 0; i < this.mask.length; i += 1) {
      const p = 4 * i;
      this.mask[i] = rgba[p + 3] !== 0 && (rgba[p] || rgba[p + 1] || rgba[p + 2]) ? 1 : 0;
    }
    this.context.clearRect(0, 0, this.width, this.height);
    this.reset(false);
    return null;
  }

  /** Forget the strokes: the mask as it now is becomes the start. */
  reset(edited) {
    this.undo = [];
    this.edited = edited;
    this.count = this.mask ? this.mask.reduce((sum, v) => sum + v, 0) : 0;
    this.redraw(0, 0, this.width, this.height);
    this.changed();
  }

  clear() {
    if (!this.mask) return;
    this.remember({ x: 0, y: 0, w: this.width, h: this.height }, this.mask.slice());
    this.mask.fill(0);
    this.count = 0;
    this.edited = true;
    this.redraw(0, 0, this.width, this.height);
    this.changed();
  }

  // --- showing it ------------------------------------------------------------------------------

  /** Size the picture to the panel: as large as fits, at most MAX_ENLARGE times. */
  fit() {
    if (!this.width) return;
    const room = $("painter").clientWidth;
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
    $("brush-size-value").textContent = `${this.size.value} px`;
  }

  /** The overlay's pixels in the box, from the mask. */
  redraw(x, y, w, h) {
    if (!this.mask || w <= 0 || h <= 0) return;
    const pixels = this.context.createImageData(w, h);
    const data = pixels.data;
    for (let row = 0; row < h; row += 1) {
      const from = (y + row) * this.width + x;
      for (let col = 0; col < w; col += 1) {
        if (this.mask[from + col]) data.set(PAINT, 4 * (row * w + col));
      }
    }
    this.context.putImageData(pixels, x, y);
  }

  changed(problem = null) {
    const info = $("mask-info");
    const total = this.width * this.height;
    if (problem) info.textContent = problem;
    else if (!total) info.textContent = "Choose an image first, then paint over what to fill.";
    else if (!this.count) info.textContent = "Nothing painted: paint over what to fill.";
    else {
      const percent = (100 * this.count / total).toFixed(1);
      info.textContent = `${this.count} pixels to fill (${percent} % of the image)`;
    }
    $("mask-undo").disabled = !this.undo.length;
    $("mask-clear").disabled = !this.count;
  }

  // --- painting --------------------------------------------------------------------------------

  /** The pointer's position in image pixels (fractional). */
  at(event) {
    const box = this.canvas.getBoundingClientRect();
    return {
      x: (event.clientX - box.left) * this.width / box.width,
      y: (event.clientY - box.top) * this.height / box.height,
    };
  }

  down(event) {
    if (!this.mask || event.button !== 0) return;
    event.preventDefault();
    this.canvas.setPointerCapture(event.pointerId);
    const point = this.at(event);
    this.stroke = { before: this.mask.slice(), last: point, box: null };
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
    this.edited = true;
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

  /** Paint (or erase) the segment from ``a`` to ``b`` with the brush (see :func:`stamp`). */
  paint(a, b) {
    const radius = Math.max(0.5, Number(this.size.value) / 2);
    const value = this.erasing ? 0 : 1;
    const drawn = stamp(this.mask, this.width, this.height, a, b, radius, value, (was) => {
      this.count += value - was;
    });
    if (!drawn) return;
    const box = this.stroke.box;
    this.stroke.box = box ? union(box, drawn) : drawn;
    this.context.clearRect(drawn.x, drawn.y, drawn.w, drawn.h);
    this.redraw(drawn.x, drawn.y, drawn.w, drawn.h);
    this.changed();
  }

  /** Keep the box of ``before`` (the whole mask as it was) for Undo. */
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
      const was = this.mask.subarray(at, at + w);
      for (let col = 0; col < w; col += 1) this.count += pixels[row * w + col] - was[col];
      was.set(pixels.subarray(row * w, (row + 1) * w));
    }
    this.edited = true;
    this.context.clearRect(x, y, w, h);
    this.redraw(x, y, w, h);
    this.changed();
  }

  // --- sending it ------------------------------------------------------------------------------

  /** The painted mask as a PNG of the image's natural size: white painted, black kept. */
  async png() {
    const canvas = document.createElement("canvas");
    canvas.width = this.width;
    canvas.height = this.height;
    const context = canvas.getContext("2d");
    const pixels = context.createImageData(this.width, this.height);
    const data = pixels.data;
    for (let i = 0; i < this.mask.length; i += 1) {
      const v = this.mask[i] ? 255 : 0;
      data[4 * i] = data[4 * i + 1] = data[4 * i + 2] = v;
      data[4 * i + 3] = 255;
    }
    context.putImageData(pixels, 0, 0);
    return new Promise((resolve, reject) => canvas.toBlob(
      (blob) => (blob ? resolve(blob) : reject(new Error("the mask could not be made"))),
      "image/png"));
  }
}
