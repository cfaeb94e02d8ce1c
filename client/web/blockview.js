// The block size shown where it matters: a square outline of the block, to scale, over the
// texture it is cut from, following the block field and the preset under the pointer or the
// focus, so that "Medium" or "48" means something before anything is run.

export class BlockView {
  /** ``figure``: the <figure> holding an <img> and the outline; built here. */
  constructor(figure) {
    this.figure = figure;
    this.image = document.createElement("img");
    this.image.className = "block-texture";
    this.image.alt = "";
    this.outline = document.createElement("div");
    this.outline.className = "block-outline";
    this.outline.id = "block-outline";
    this.caption = document.createElement("figcaption");
    this.caption.id = "block-caption";
    const frame = document.createElement("div");
    frame.className = "block-frame";
    frame.append(this.image, this.outline);
    figure.append(frame, this.caption);
    figure.hidden = true;
    this.file = null;
    this.url = null;
    this.size = null; // the texture's [width, height]
    this.block = null; // the field's block side, or null (auto, or not a number)
    this.trying = null; // a preset's side, while under the pointer or the focus
  }

  /** The image the blocks are cut from (``file``, ``size`` its [width, height]), or none. */
  setSource(file, size, name) {
    if (file !== this.file) {
      if (this.url) URL.revokeObjectURL(this.url);
      this.url = file ? URL.createObjectURL(file) : null;
      this.file = file;
      if (this.url) this.image.src = this.url;
      else this.image.removeAttribute("src");
    }
    this.size = file && size ? size : null;
    this.name = name || file?.name || "";
    this.draw();
  }

  /** The block field's text ("48", "" for auto). */
  setBlock(text) {
    const side = Number(text);
    this.block = text !== "" && Number.isInteger(side) && side > 0 ? side : null;
    this.draw();
  }

  /** A preset's side shown while it is considered (null: back to the field's). */
  preview(side) {
    this.trying = side;
    this.draw();
  }

  draw() {
    const side = this.trying ?? this.block;
    this.figure.hidden = !this.size;
    if (!this.size) return;
    const [width, height] = this.size;
    this.outline.hidden = !side;
    const what = `${this.name} (${width} × ${height})`;
    if (!side) {
      this.caption.textContent = `Give a block side in pixels to see it on ${what}.`;
      return;
    }
    // Centred on the texture, to scale; a block larger than the texture overflows its frame.
    const w = (side / width) * 100;
    const h = (side / height) * 100;
    Object.assign(this.outline.style, {
      width: `${w}%`, height: `${h}%`, left: `${(100 - w) / 2}%`, top: `${(100 - h) / 2}%`,
    });
    const share = Math.round((side / Math.min(width, height)) * 100);
    const larger = side > Math.min(width, height) ? ": larger than the texture" : "";
    this.caption.textContent = `A block of ${side} × ${side} px on ${what}, ` +
      `${share} % of its shorter side${larger}` + (this.trying ? " (preset)" : "");
  }
}
