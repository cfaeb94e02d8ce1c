// The output size of a synthesis, set in one click: square presets (512, 1K, 2K, 4K), the
// texture's aspect, and a lock that keeps the width and height in proportion while either is
// typed.

/** The presets: the longer side of the output, in pixels. */
export const SIZE_PRESETS = [
  { name: "512", side: 512 },
  { name: "1K", side: 1024 },
  { name: "2K", side: 2048 },
  { name: "4K", side: 4096 },
];

/** [width, height] of a preset's ``side`` at the aspect ``ratio`` (width / height; null:
 * square): the longer side is ``side``, the other in proportion, at least 1. */
export function presetSize(side, ratio) {
  if (!ratio) return [side, side];
  return ratio >= 1
    ? [side, Math.max(1, Math.round(side / ratio))]
    : [Math.max(1, Math.round(side * ratio)), side];
}

export class SizePresets {
  /**
   * ``box``: the group the buttons go in (``#size-presets``), its first child the label;
   * ``changed()``: called after a button or the lock set a field (the request is shown anew).
   */
  constructor(box, changed) {
    this.box = box;
    this.changed = changed;
    this.width = null;
    this.height = null;
    this.ratio = null; // width / height while the lock is on
    this.textureSize = null;
    this.buttons = document.createElement("span");
    this.buttons.className = "size-buttons";
    for (const preset of SIZE_PRESETS) {
      const button = document.createElement("button");
      button.type = "button";
      button.className = "size-preset";
      button.dataset.side = String(preset.side);
      button.textContent = preset.name;
      button.addEventListener("click", () => this.setSide(preset.side));
      this.buttons.append(button);
    }
    this.aspect = document.createElement("button");
    this.aspect.type = "button";
    this.aspect.id = "size-aspect";
    this.aspect.textContent = "Texture's aspect";
    this.aspect.addEventListener("click", () => this.textureAspect());
    const lock = document.createElement("label");
    lock.className = "size-lock";
    this.lock = document.createElement("input");
    this.lock.type = "checkbox";
    this.lock.id = "size-lock";
    this.lock.addEventListener("change", () => this.setLock(this.lock.checked));
    lock.append(this.lock, " Keep the aspect");
    this.info = document.createElement("span");
    this.info.className = "hint size-info";
    this.info.id = "size-info";
    this.info.setAttribute("aria-live", "polite");
    box.append(this.buttons, this.aspect, lock, this.info);
  }

  /** The width and height fields of the operation's form (null: it has none, the group is
   * hidden). Called each time the form is built anew. */
  attach(width, height) {
    this.width = width;
    this.height = height;
    this.box.hidden = !width || !height;
    if (!width || !height) return;
    for (const [input, other, along] of [[width, height, true], [height, width, false]]) {
      input.addEventListener("input", () => this.follow(input, other, along));
    }
    this.setLock(this.lock.checked);
    this.describe();
  }

  /** The texture's [width, height] (the smallest of several), or null. */
  setTexture(size) {
    this.textureSize = size;
    this.aspect.disabled = !size;
    this.aspect.title = size
      ? `Make the output ${size[0]} : ${size[1]}, as the texture, and keep it so`
      : "Choose a texture first";
    this.describe();
  }

  /** The output's [width, height] as typed, or null where either is not a whole number. */
  size() {
    const w = Number(this.width?.value);
    const h = Number(this.height?.value);
    return Number.isInteger(w) && Number.isInteger(h) && w > 0 && h > 0 ? [w, h] : null;
  }

  setSide(side) {
    this.set(...presetSize(side, this.lock.checked ? this.ratio : null));
  }

  /** The texture's proportions, the output's longer side kept; the lock then keeps them. */
  textureAspect() {
    if (!this.textureSize) return;
    const [tw, th] = this.textureSize;
    const now = this.size() || [512, 512];
    this.lock.checked = true;
    this.ratio = tw / th;
    this.set(...presetSize(Math.max(...now), this.ratio));
  }

  setLock(on) {
    const now = this.size();
    this.ratio = on && now ? now[0] / now[1] : null;
    if (on && !now) this.lock.checked = false;
    this.describe();
  }

  /** A field typed in while the lock is on: the other follows, in proportion. */
  follow(input, other, along) {
    if (!this.lock.checked || !this.ratio) return this.describe();
    const value = Number(input.value);
    if (Number.isInteger(value) && value > 0) {
      other.value = String(Math.max(1, Math.round(along ? value / this.ratio : value * this.ratio)));
    }
    this.describe();
  }

  set(width, height) {
    this.width.value = String(width);
    this.height.value = String(height);
    this.describe();
    this.changed();
  }

  /** "1024 × 683, 0.7 megapixels, 1.50 : 1 (kept)" under the buttons. */
  describe() {
    const size = this.size();
    if (!size) {
      this.info.textContent = "";
      return;
    }
    const megapixels = (size[0] * size[1]) / 1e6;
    const aspect = `${(size[0] / size[1]).toFixed(2)} : 1`;
    this.info.textContent = `${size[0]} × ${size[1]}, ${megapixels.toFixed(1)} megapixels, ` +
      `${aspect}${this.lock.checked ? " (kept)" : ""}`;
  }
}
