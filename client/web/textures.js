// The textures of a synthesis or a Wang tile set: one example or several, quilted together.
// Shown as thumbnails in their order, each movable and removable, each with its weight (how
// much to prefer it) once there are several. The file input keeps the files, in this order.

import { fileWords, thumbnail } from "./inputs.js";

/** The weight a texture starts with; weights that all read as this one are not sent. */
const DEFAULT_WEIGHT = "1";

/**
 * A button of a file list's item: ``<prefix>-<action>`` its class, ``data-action`` and
 * ``data-index`` what :func:`editFiles` reads, ``label`` its tooltip and accessible name.
 */
export function listButton(prefix, action, text, label, disabled, index) {
  const button = document.createElement("button");
  button.type = "button";
  button.className = `${prefix}-${action}`;
  button.textContent = text;
  button.title = label;
  button.setAttribute("aria-label", label);
  button.disabled = disabled;
  button.dataset.index = String(index);
  button.dataset.action = action;
  return button;
}

/**
 * A click on a file list's "earlier", "later" or "remove" button (``data-action``,
 * ``data-index``): the input's files reordered or one taken out, in place. Returns where the
 * focus goes (``{index, action}``), or null when the click changed nothing.
 */
export function editFiles(input, event) {
  const button = event.target.closest("button[data-action]");
  if (!button) return null;
  const files = [...input.files];
  const index = Number(button.dataset.index);
  const action = button.dataset.action;
  let focusIndex = index;
  if (action === "remove") {
    files.splice(index, 1);
    focusIndex = Math.min(index, files.length - 1);
  } else {
    const other = action === "earlier" ? index - 1 : index + 1;
    if (other < 0 || other >= files.length) return null;
    [files[index], files[other]] = [files[other], files[index]];
    focusIndex = other;
  }
  const chosen = new DataTransfer();
  for (const file of files) chosen.items.add(file);
  input.files = chosen.files;
  return { index: focusIndex, action };
}

/**
 * After a file list is drawn anew: the focus back on the button of the edit ``focus``
 * (``{index, action}``) made, else on another of that item's, else on the last button, else
 * on ``fallback`` (the file input). Nothing is done without an edit.
 */
export function restoreFocus(list, focus, fallback) {
  if (!focus) return;
  const buttons = [...list.querySelectorAll("button:not(:disabled)")];
  const same = buttons.find((b) => b.dataset.index === String(focus.index) &&
    b.dataset.action === focus.action);
  const near = buttons.find((b) => b.dataset.index === String(focus.index));
  (same || near || buttons.at(-1) || fallback).focus();
}

export class TextureList {
  /**
   * ``input``: the file input holding the textures; ``list``: the <ol> they are shown in.
   * An edit (move, remove) sets the input's files and sends it a "change" event; the page
   * then calls :meth:`render` again, with :attr:`focus` saying where the focus goes.
   */
  constructor(input, list) {
    this.input = input;
    this.list = list;
    this.weights = new WeakMap(); // File -> the text of its weight box
    this.urls = new Map(); // File -> the object URL of its thumbnail
    this.focus = null; // {index, action} of the last edit, for the next render
    list.addEventListener("click", (event) => this.edit(event));
    list.addEventListener("input", (event) => {
      const box = event.target.closest("input.texture-weight");
      const file = box && this.input.files[Number(box.dataset.index)];
      if (file) this.weights.set(file, box.value);
    });
  }

  /** The chosen files, in order. */
  get files() {
    return [...this.input.files];
  }

  /**
   * Show the list: every texture with its weight and buttons (``several`` true, for an
   * operation that quilts several together), else the one the operation takes.
   * ``sizes``: [width, height] or null (not readable here) of each file; ``details``: each
   * one's :func:`imageInfo` (bit depth and channels), or null.
   */
  render(files, sizes, several, details = []) {
    for (const [file, url] of this.urls) {
      if (!files.includes(file)) {
        URL.revokeObjectURL(url);
        this.urls.delete(file);
      }
    }
    const shown = several ? files : files.slice(0, 1);
    const weighed = shown.length > 1;
    this.list.replaceChildren(...shown.map((file, index) => {
      const item = document.createElement("li");
      if (!this.urls.has(file)) this.urls.set(file, URL.createObjectURL(file));
      const name = document.createElement("span");
      name.className = "texture-name";
      const size = sizes[index] ? `${sizes[index][0]} × ${sizes[index][1]}` : "not readable here";
      const words = fileWords(details[index]);
      name.textContent = `${file.name} (${size}${words ? `, ${words}` : ""})`;
      item.append(thumbnail(this.urls.get(file)), name);
      if (weighed) {
        const weight = document.createElement("input");
        weight.type = "number";
        weight.className = "texture-weight";
        weight.id = `texture-weight-${index}`;
        weight.min = "0";
        weight.step = "any";
        weight.inputMode = "decimal";
        weight.value = this.weights.get(file) ?? DEFAULT_WEIGHT;
        weight.dataset.index = String(index);
        weight.title = "Weight: how much to prefer this texture's blocks (a number above 0)";
        weight.setAttribute("aria-label", `Weight of ${file.name}`);
        item.append(weight);
      }
      for (const [action, text, label, disabled] of [
        ["earlier", "↑", `Move ${file.name} earlier`, index === 0],
        ["later", "↓", `Move ${file.name} later`, index === files.length - 1],
        ["remove", "✕", `Remove ${file.name}`, false],
      ]) {
        if (action !== "remove" && !weighed) continue;
        item.append(listButton("texture", action, text, label, disabled, index));
      }
      return item;
    }));
    this.list.hidden = !files.length;
    restoreFocus(this.list, this.focus, this.input);
    this.focus = null;
  }

  /** A click on a texture's button: move it one place or take it out. */
  edit(event) {
    const focus = editFiles(this.input, event);
    if (!focus) return;
    this.focus = focus;
    this.input.dispatchEvent(new Event("change", { bubbles: true }));
  }

  /**
   * The ``weights`` option as an options field reads it (options.js): ``{set, value}``, set
   * only with several textures and a weight other than 1; throws an Error naming the texture
   * (``error.input``: its box) for a weight that is not a number above 0.
   */
  readWeights() {
    const files = this.files;
    if (files.length < 2) return { set: false, value: undefined };
    const boxes = [...this.list.querySelectorAll("input.texture-weight")];
    const values = files.map((file, index) => {
      const box = boxes.find((b) => b.dataset.index === String(index));
      const text = (this.weights.get(file) ?? DEFAULT_WEIGHT).trim();
      const value = Number(text);
      if (text === "" || !Number.isFinite(value) || value <= 0) {
        box?.setAttribute("aria-invalid", "true");
        const error = new Error(`weights: the weight of ${file.name} must be a number above 0` +
          (text ? ` (not ${text})` : ""));
        error.input = box || this.input;
        throw error;
      }
      box?.removeAttribute("aria-invalid");
      return value;
    });
    if (values.every((value) => value === Number(DEFAULT_WEIGHT))) {
      return { set: false, value: undefined };
    }
    return { set: true, value: values };
  }
}
