// The layers of a matting, bottom first: each a thumbnail with its name, size and depth, moved
// one place or taken out with its buttons, and, for an opaque photo, the trimap that extracts
// its alpha first. The file input keeps the layers, in this order.

import { alphaOf } from "./alpha.js";
import { fileWords, imageSize, infoOf, thumbnail } from "./inputs.js";
import { editFiles, listButton, restoreFocus } from "./textures.js";

export class LayerList {
  /**
   * ``input``: the file input holding the layers; ``list``: the <ol> they are shown in;
   * ``changed()``: called once the list is drawn anew (the first layer may be another: the
   * block presets follow it).
   */
  constructor(input, list, changed) {
    this.input = input;
    this.list = list;
    this.changed = changed;
    // The trimap chosen for a layer (layer File -> trimap File): the layer is then an opaque
    // photo, its alpha extracted first. Kept by file, so that it follows its layer when the
    // layers are reordered, and goes with it.
    this.trimaps = new WeakMap();
    this.urls = new WeakMap(); // File -> the object URL of its thumbnail
    this.token = 0; // the latest drawing: an earlier one still reading files is dropped
    this.file = null; // the first (bottom) layer
    this.size = null; // its [width, height]
    input.addEventListener("change", () => this.render());
    list.addEventListener("click", (event) => this.edit(event));
    list.addEventListener("change", (event) => this.chooseTrimap(event));
  }

  /** The trimap chosen for the layer ``file``, or null. */
  trimapOf(file) {
    return this.trimaps.get(file) || null;
  }

  /** Draw the list; ``focus`` (``{index, action}``): where the focus goes after an edit. */
  async render(focus = null) {
    const files = [...this.input.files];
    const token = (this.token += 1);
    const trimaps = files.map((file) => this.trimapOf(file));
    const [known, details, kinds, trimapSizes] = await Promise.all([
      Promise.all(files.map(imageSize)),
      Promise.all(files.map(infoOf)),
      Promise.all(files.map(alphaOf)),
      Promise.all(trimaps.map((trimap) => (trimap ? imageSize(trimap) : null))),
    ]);
    if (token !== this.token) return;
    this.size = known[0] || null;
    this.file = files[0] || null;
    this.list.replaceChildren(...files.map((file, index) => {
      const item = document.createElement("li");
      const name = document.createElement("span");
      name.className = "layer-name";
      const where = files.length > 1 && index === 0 ? ", bottom"
        : files.length > 1 && index === files.length - 1 ? ", top" : "";
      const size = known[index] ? `${known[index][0]} × ${known[index][1]}` : "not readable here";
      const words = fileWords(details[index]);
      name.textContent = `${file.name} (${size}${words ? `, ${words}` : ""}${where})`;
      item.append(thumbnail(this.urlOf(file)), name);
      for (const [action, text, label, disabled] of [
        ["earlier", "↑", `Move ${file.name} earlier (towards the bottom)`, index === 0],
        ["later", "↓", `Move ${file.name} later (towards the top)`, index === files.length - 1],
        ["remove", "✕", `Remove ${file.name}`, false],
      ]) {
        item.append(listButton("layer", action, text, label, disabled, index));
      }
      item.append(this.trimapRow(file, index, kinds[index], known[index], trimapSizes[index]));
      return item;
    }));
    this.list.hidden = !files.length;
    if (focus?.action === "trimap") {
      const row = this.list.querySelector(`.layer-trimap[data-index="${focus.index}"]`);
      (row?.querySelector("button, input") || this.input).focus();
    } else {
      restoreFocus(this.list, focus, this.input);
    }
    this.changed();
  }

  /** The object URL of a layer's thumbnail, made once per file. */
  urlOf(file) {
    if (!this.urls.has(file)) this.urls.set(file, URL.createObjectURL(file));
    return this.urls.get(file);
  }

  /**
   * Under a layer: its trimap, chosen with "Trimap…" (a file input in a label), named with its
   * size (and a word where it is not the layer's), and taken off with ✕. A layer with alpha
   * of its own needs none: it says so instead.
   */
  trimapRow(file, index, kind, size, trimapSize) {
    const row = document.createElement("div");
    row.className = "layer-trimap";
    row.dataset.index = String(index);
    const trimap = this.trimapOf(file);
    const info = document.createElement("span");
    info.className = "layer-trimap-info";
    if (kind === "alpha" && !trimap) {
      info.textContent = "has alpha: laid as it is";
      row.append(info);
      return row;
    }
    const pick = document.createElement("label");
    pick.className = "layer-trimap-pick";
    const chooser = document.createElement("input");
    chooser.type = "file";
    chooser.accept = "image/png,image/jpeg";
    chooser.className = "visually-hidden layer-trimap-file";
    chooser.dataset.index = String(index);
    chooser.setAttribute("aria-label", `Trimap of ${file.name} (optional)`);
    pick.append(trimap ? "Other trimap…" : "Trimap…", chooser);
    row.append(pick, info);
    if (!trimap) {
      info.textContent = "an opaque photo: its trimap extracts its alpha first";
      return row;
    }
    let text = trimapSize ? `trimap ${trimap.name} (${trimapSize[0]} × ${trimapSize[1]})`
      : `trimap ${trimap.name}: not an image this browser can show`;
    if (trimapSize && size && (trimapSize[0] !== size[0] || trimapSize[1] !== size[1])) {
      text += `, not the layer's ${size[0]} × ${size[1]}`;
    }
    if (kind === "alpha") text += "; the layer has alpha already: take the trimap off";
    info.textContent = text;
    const off = document.createElement("button");
    off.type = "button";
    off.className = "layer-untrimap";
    off.textContent = "✕";
    off.dataset.index = String(index);
    off.title = `Take the trimap off ${file.name}`;
    off.setAttribute("aria-label", off.title);
    row.append(off);
    return row;
  }

  /** A trimap chosen for a layer: kept for it, and shown. */
  chooseTrimap(event) {
    const chooser = event.target.closest("input.layer-trimap-file");
    if (!chooser) return;
    const index = Number(chooser.dataset.index);
    const layer = this.input.files[index];
    const trimap = chooser.files[0];
    if (!layer || !trimap) return;
    this.trimaps.set(layer, trimap);
    this.render({ index, action: "trimap" });
  }

  /** A click on a layer's button: move it one place, take it out, or take its trimap off. */
  edit(event) {
    const off = event.target.closest("button.layer-untrimap");
    if (off) {
      const index = Number(off.dataset.index);
      const layer = this.input.files[index];
      if (layer) this.trimaps.delete(layer);
      this.render({ index, action: "trimap" });
      return;
    }
    const focus = editFiles(this.input, event);
    if (focus) this.render(focus);
  }
}
