// Where images come into the page: each image box's file input, a file dropped on the box, or
// an image pasted from the clipboard; and what was chosen, shown in the box as a thumbnail with
// its size, bit depth and channels.

import { depthWords, imageInfo } from "./imageinfo.js";

/** The infos read so far, by file (a box drawn again does not read its files again). */
const infos = new WeakMap();

/** A promise of :func:`imageInfo` of ``file``, read once. */
export function infoOf(file) {
  if (!infos.has(file)) infos.set(file, imageInfo(file));
  return infos.get(file);
}

/** Sizes of the files read so far (a reordered layer is not decoded again). */
const sizes = new WeakMap();

/** [width, height] of an image file, or null where this browser cannot decode it. */
export async function imageSize(file) {
  if (!sizes.has(file)) {
    sizes.set(file, createImageBitmap(file).then((bitmap) => {
      const size = [bitmap.width, bitmap.height];
      bitmap.close();
      return size;
    }).catch(() => null)); // not an image the browser reads: the service will say why
  }
  return sizes.get(file);
}

/** "8-bit RGB PNG" of a file's info, or "" where it is not a PNG or JPEG read here. */
export function fileWords(info) {
  return info ? `${depthWords(info)} ${info.format}` : "";
}

/** "gravel.png: 256 × 256 pixels, 8-bit RGB PNG" (the header's size, else ``size``). */
export function describeImage(file, size, info) {
  const [width, height] = info ? [info.width, info.height] : size || [];
  if (width === undefined) return `${file.name}: not an image this browser can show`;
  const words = fileWords(info);
  return `${file.name}: ${width} × ${height} pixels${words ? `, ${words}` : ""}`;
}

/** A thumbnail <img> of ``file`` (``url``: its object URL), described by the text beside it. */
export function thumbnail(url) {
  const image = document.createElement("img");
  image.className = "thumb";
  image.src = url;
  image.alt = ""; // the name, size and depth beside it say which
  image.decoding = "async";
  return image;
}

/**
 * The files chosen in one image box, shown under it: a thumbnail each with its name, size, bit
 * depth and channels. For the boxes with no list of their own (the texture's and the layers'
 * lists show theirs, with their order and buttons).
 */
export class FilePreview {
  /** ``input``: the box's file input; the list goes at the end of ``box``. */
  constructor(input, box) {
    this.input = input;
    this.list = document.createElement("ul");
    this.list.className = "input-thumbs";
    this.list.id = `${input.id}-thumbs`;
    this.list.setAttribute("aria-label", `Chosen: ${labelOf(input)}`);
    this.list.hidden = true;
    this.urls = new Map(); // File -> object URL
    box.append(this.list);
    input.addEventListener("change", () => this.render());
  }

  async render() {
    const files = [...this.input.files];
    const token = (this.token = (this.token || 0) + 1);
    const known = await Promise.all(files.map(infoOf));
    if (token !== this.token) return; // a later choice is being shown
    for (const [file, url] of this.urls) {
      if (!files.includes(file)) {
        URL.revokeObjectURL(url);
        this.urls.delete(file);
      }
    }
    this.list.replaceChildren(...files.map((file, index) => {
      if (!this.urls.has(file)) this.urls.set(file, URL.createObjectURL(file));
      const item = document.createElement("li");
      const text = document.createElement("span");
      text.className = "input-name";
      text.textContent = describeImage(file, null, known[index]);
      item.append(thumbnail(this.urls.get(file)), text);
      return item;
    }));
    this.list.hidden = !files.length;
  }
}

/** The visible text of a file input's label ("Target", "Companion maps (optional)"). */
function labelOf(input) {
  return [...(input.labels || [])].map((label) => label.textContent.trim()).join(" ") ||
    input.getAttribute("aria-label") || input.id;
}

/** Put ``files`` into ``input`` (added to those there for an input of several), as a choice
 * made with its own dialog: its "change" event sent. */
function give(input, files, add = false) {
  const chosen = new DataTransfer();
  const kept = input.multiple && add ? [...input.files] : [];
  for (const file of [...kept, ...(input.multiple ? files : files.slice(0, 1))]) {
    chosen.items.add(file);
  }
  input.files = chosen.files;
  input.dispatchEvent(new Event("change", { bubbles: true }));
}

/** Drag-and-drop onto each image box (``.drop[data-input]``): the dropped files go into its
 * file input, in place of what was there. */
export function enableDrops() {
  for (const drop of document.querySelectorAll(".drop")) {
    const input = document.getElementById(drop.dataset.input);
    drop.addEventListener("dragover", (event) => {
      event.preventDefault();
      drop.classList.add("over");
    });
    drop.addEventListener("dragleave", () => drop.classList.remove("over"));
    drop.addEventListener("drop", (event) => {
      event.preventDefault();
      drop.classList.remove("over");
      const files = [...(event.dataTransfer?.files || [])];
      if (files.length) give(input, files);
    });
  }
}

/**
 * Paste from the clipboard: an image pasted anywhere on the page goes into the image box that
 * holds the focus (or was last used), else into the first shown box with nothing chosen, else
 * the first shown box; a box of several gets it added to its files. ``announce(text)`` says
 * where it went. A paste of text into a text field is left alone.
 */
export function enablePaste(announce) {
  let last = null; // the .drop box last focused or dropped on
  document.addEventListener("focusin", (event) => {
    const drop = event.target.closest?.(".drop[data-input]");
    if (drop) last = drop;
  });
  document.addEventListener("paste", (event) => {
    const files = [...(event.clipboardData?.files || [])]
      .filter((file) => file.type.startsWith("image/"));
    if (!files.length) return;
    const drop = pasteTarget(event.target, last);
    if (!drop) return;
    event.preventDefault();
    const input = document.getElementById(drop.dataset.input);
    // A pasted screenshot is "image.png" in every browser: name it for what it became.
    const named = files.map((file, i) => (file.name && file.name !== "image.png" ? file
      : new File([file], `pasted${files.length > 1 ? `-${i + 1}` : ""}.${extension(file)}`,
        { type: file.type, lastModified: Date.now() })));
    give(input, named, true);
    last = drop;
    announce(`Pasted ${named.map((file) => file.name).join(", ")} into ${labelOf(input)}.`);
  });
}

function extension(file) {
  return { "image/jpeg": "jpg", "image/png": "png" }[file.type] || "png";
}

/** Whether an element is shown (not inside anything hidden). */
function shown(element) {
  return Boolean(element) && element.checkVisibility();
}

function pasteTarget(target, last) {
  const boxes = [...document.querySelectorAll(".drop[data-input]")].filter(shown);
  const here = target?.closest?.(".drop[data-input]");
  if (here && shown(here)) return here;
  if (last && shown(last)) return last;
  const empty = boxes.find((box) => !document.getElementById(box.dataset.input).files.length);
  return empty || boxes[0] || null;
}
