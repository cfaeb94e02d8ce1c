// The mask of a fill, painted on the image (painter.js): one mask pixel per image pixel,
// painted and erased with a round brush, shown half-transparent, and sent as a PNG: white
// where painted, black elsewhere.

import { Painter } from "./painter.js";

const $ = (id) => document.getElementById(id);

/** The painted area's colour on the overlay (the overlay itself is half-transparent). */
const PAINT = [255, 0, 110, 255];
/** How the mask is sent: white painted, black kept, opaque. */
const SENT = [[0, 0, 0, 255], [255, 255, 255, 255]];

function decoded(file) {
  // The file's own values: no colour management, no premultiplication (a mask is data).
  return createImageBitmap(file, { colorSpaceConversion: "none", premultiplyAlpha: "none" });
}

export class MaskPainter extends Painter {
  constructor() {
    super(
      {
        editor: "mask-editor",
        image: "mask-image",
        canvas: "mask-canvas",
        cursor: "brush-cursor",
        size: "brush-size",
        sizeValue: "brush-size-value",
        undo: "mask-undo",
        clear: "mask-clear",
        room: "painter",
      },
      [null, PAINT],
      2,
    );
    this.edited = false; // changed since the mask file was loaded (or painted from nothing)
    this.ready = Promise.resolve(); // the latest image, once shown
    this.imageLoads = 0; // so that only the latest image and mask file are shown
    this.maskLoads = 0;
  }

  /** The brush's label: 1 paints, 0 erases. */
  get brush() {
    return document.querySelector('input[name="brush"]:checked').value === "erase" ? 0 : 1;
  }

  /** The painted pixels (1 where painted), row by row; null without an image. */
  get mask() {
    return this.labels;
  }

  /** Painted pixels. */
  get count() {
    return this.painted;
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
    this.forget();
    if (file) {
      const shown = await this.show(file);
      if (!shown) {
        if (load === this.imageLoads) this.changed("This image cannot be shown here.");
        return;
      }
      if (load !== this.imageLoads) return;
      this.start(12);
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
    if (!this.labels) return "sent as it is (there is no image here to show it on)";
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
    for (let i = 0; i < this.labels.length; i += 1) {
      const p = 4 * i;
      this.labels[i] = rgba[p + 3] !== 0 && (rgba[p] || rgba[p + 1] || rgba[p + 2]) ? 1 : 0;
    }
    this.context.clearRect(0, 0, this.width, this.height);
    this.reset(false);
    return null;
  }

  /** Forget the strokes: the mask as it now is becomes the start. */
  reset(edited) {
    this.edited = edited;
    this.recount();
    this.changed();
  }

  stroked() {
    this.edited = true;
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
    this.cursor.hidden = false;
  }

  /** The painted mask as a PNG of the image's natural size: white painted, black kept. */
  png() {
    return super.png(SENT, "the mask");
  }
}
