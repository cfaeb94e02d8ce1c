// The page: pick an operation and images, set options, run a job on the service, follow its
// progress, cancel it, and show what came back. Talks to the HTTP API only (api.js).

import {
  ApiError, downloadName, followEvents, getBlob, getFile, getJson, request,
} from "./api.js";
import { AlphaPanel, alphaOf, summariesOf, summaryLine, summaryStats } from "./alpha.js";
import { MaskPainter } from "./mask.js";
import { PRESETS, buildOptions, presetBlock } from "./options.js";
import { TextureList, editFiles, listButton } from "./textures.js";
import { Viewer } from "./viewer.js";
import { WangPreview } from "./wang.js";

const $ = (id) => document.getElementById(id);

const OPERATIONS = {
  synthesize: {
    path: "/synthesize",
    hint: "A larger texture of any size from the sample, or from several quilted together.",
    textureLabel: "Texture",
    several: true,
  },
  transfer: {
    path: "/transfer",
    hint: "The target image rendered in the texture (texture transfer).",
    textureLabel: "Texture",
  },
  tile: {
    path: "/tile",
    hint: "The image itself, made to repeat seamlessly (same size, its centre kept).",
    textureLabel: "Image",
  },
  matte: {
    path: "/matte",
    hint: "Textures laid on the surface of an object in the target image, following its " +
      "shape and shading (texture matting). The silhouette says where the surface is.",
    targetHint: "The picture of the object; the output has its size.",
    input: "Target",
    presetsFrom: "the first layer",
    noSeams: "A matting result has no block seams: each layer is quilted on its own, then " +
      "laid on the surface. The clusters download shows its patches.",
    companions: {
      normals: "normals (the estimated normal map)",
      clusters: "clusters (the patches in colours)",
    },
  },
  fill: {
    path: "/fill",
    hint: "What the mask marks (a stain, a logo, a cable) filled from the rest of the image; " +
      "every other pixel is kept as it is. Paint the mask on the image or choose one.",
    textureLabel: "Image",
    presetsFrom: "this image",
    input: "Before",
    result: "After",
    view: "side",
    noSeams: "A fill has no block seams to show: compare it with the image side by side.",
  },
  extend: {
    path: "/extend",
    hint: "The image grown past its borders (uncrop): the pixels added on each side " +
      "synthesized from the image, the image itself kept as it is.",
    textureLabel: "Image",
    presetsFrom: "this image",
    input: "Before",
    result: "After",
    view: "side",
    noSeams: "An extended image has no block seams to show: compare it with the image side " +
      "by side.",
  },
  wang: {
    path: "/wang-tiles",
    hint: "A set of Wang tiles quilted from the texture (or several): a tile for every " +
      "combination of edge colours, so that tiles whose edges share a colour join " +
      "seamlessly and lay out in endless arrangements that never repeat (Cohen et al. 2003). " +
      "The result is the atlas of the tiles, its manifest and a 6 × 6 preview.",
    textureLabel: "Texture",
    several: true,
    result: "Atlas",
    download: "Download atlas PNG",
    view: "single",
    noSeams: "A Wang tile set's atlas has no seams to show: see the tiles laid out in the " +
      "preview below.",
    wang: true,
  },
};

/** The texture box's hint with no file chosen: one texture, or one or more. */
const TEXTURE_HINT = "PNG or JPEG. Drop a file here or choose one.";
const TEXTURES_HINT = "PNG or JPEG, one or more (of the same channels). Drop files here or " +
  "choose them: several are quilted together.";

/** The sides an extension adds pixels on (ExtendOptions). */
const SIDES = ["top", "bottom", "left", "right"];

/** The target's hint outside a matting (in index.html). */
const TARGET_HINT = "The image to render in the texture; the output has its size.";

/** The job's figures under the result: labels of the stats that need more than their name. */
const STAT_LABELS = { light: "light (x, y, z)", layer_size: "layer size" };

const FINAL = new Set(["done", "failed", "cancelled"]);
const POLL_MS = 500;

const state = {
  schemas: {},
  options: null,
  job: null, // {id, key, controller, seed} of the job being followed
  textureSize: null, // [width, height] of the chosen texture (the smallest of several)
  layerSize: null, // [width, height] of the first (bottom) layer of a matting
  reads: {}, // by input id: a counter, so that only the latest choice's sizes are shown
};
const viewer = new Viewer();
const painter = new MaskPainter();
const preview = new WangPreview();
const textures = new TextureList($("texture"), $("textures-order"));
// The alpha panel's method menu and the synthesis's matting option are one choice.
const alpha = new AlphaPanel({
  onMethod: (value) => {
    const matting = state.options?.input("matting");
    if (matting && [...matting.options].some((option) => option.value === value)) {
      matting.value = value;
      updateRequest();
    }
  },
});

// --- messages --------------------------------------------------------------------------------

function showError(error) {
  const box = $("error");
  if (!error) {
    box.hidden = true;
    box.replaceChildren();
    return;
  }
  const title = document.createElement("strong");
  const text = document.createElement("span");
  if (error instanceof ApiError) {
    title.textContent = "The service refused: ";
    text.textContent = error.describe();
  } else {
    title.textContent = "Error: ";
    text.textContent = error.message || String(error);
  }
  box.replaceChildren(title, text);
  box.hidden = false;
}

function setStatus(text) {
  $("status").textContent = text;
}

function setProgress(fraction) {
  const bar = $("progress");
  if (fraction === null) {
    bar.removeAttribute("value"); // indeterminate: the work gives no fractions
    $("progress-text").textContent = "…";
    return;
  }
  const percent = Math.round(Math.min(1, Math.max(0, fraction)) * 100);
  bar.value = percent;
  $("progress-text").textContent = `${percent} %`;
}

function setRunning(running) {
  $("run").disabled = running;
  $("extract").disabled = running;
  $("cancel").disabled = !running;
  $("job-form").setAttribute("aria-busy", String(running));
}

// --- the form --------------------------------------------------------------------------------

function operation() {
  return document.querySelector('input[name="operation"]:checked').value;
}

/** Whether the operation quilts several textures together (synthesis, Wang tiles). */
function several(op = operation()) {
  return Boolean(OPERATIONS[op].several);
}

function renderOptions() {
  const op = operation();
  // With several textures, the weights are asked beside each one (textures.js).
  const outside = several(op) ? { weights: () => textures.readWeights() } : {};
  state.options = buildOptions(state.schemas, op, $("main-options"), $("extra-options"),
    outside);
  const matting = state.options.input("matting");
  if (matting && [...matting.options].some((option) => option.value === alpha.method.value)) {
    matting.value = alpha.method.value;
  }
  $("texture").multiple = several(op);
  renderTextures();
  $("operation-hint").textContent = OPERATIONS[op].hint;
  if (OPERATIONS[op].textureLabel) $("texture-label").textContent = OPERATIONS[op].textureLabel;
  for (const part of document.querySelectorAll("#job-form [data-for]")) {
    part.hidden = !part.dataset.for.split(" ").includes(op);
  }
  if (!$("target").files.length) $("target-info").textContent = targetHint();
  renderPresets();
  updateRequest();
}

function targetHint() {
  return OPERATIONS[operation()].targetHint || TARGET_HINT;
}

function renderPresets() {
  const box = $("presets");
  for (const old of box.querySelectorAll("button")) old.remove();
  const block = state.options?.input("block");
  box.hidden = !block;
  if (!block) return;
  // The texture's box holds the image of a tile, fill or extension; a matting has layers.
  const many = several() && $("texture").files.length > 1;
  const source = OPERATIONS[operation()].presetsFrom ||
    (many ? "these textures" : "this texture");
  const sourceSize = source === "the first layer" ? state.layerSize : state.textureSize;
  $("presets-label").textContent = `Block size for ${source}:`;
  for (const preset of PRESETS) {
    const button = document.createElement("button");
    button.type = "button";
    button.className = "preset";
    const size = sourceSize ? presetBlock(preset.fraction, ...sourceSize) : null;
    button.textContent = size
      ? `${preset.name} (${preset.label} → ${size} px)`
      : `${preset.name} (${preset.label})`;
    button.disabled = !size;
    button.title = many
      ? `Block side ${preset.label} of the smallest texture's shorter side`
      : `Block side ${preset.label} of ${source.replace(/^this /, "the ")}'s shorter side`;
    button.addEventListener("click", () => {
      block.value = String(size);
      updateRequest();
    });
    box.append(button);
  }
}

/** The options object to send, shown as JSON under the form; throws on a bad field. */
function optionValues() {
  return state.options ? state.options.values() : {};
}

function updateRequest() {
  try {
    $("request-json").textContent = JSON.stringify(optionValues(), null, 2);
  } catch (error) {
    $("request-json").textContent = error.message;
  }
}

/** The trimap chosen for a matting's layer (layer File -> trimap File): the layer is then an
 * opaque photo, its alpha extracted first. Kept by file, so that it follows its layer when the
 * layers are reordered, and goes with it. */
const layerTrimaps = new WeakMap();

/** Sizes of the files read so far (a reordered layer is not decoded again). */
const sizes = new WeakMap();

/** [width, height] of an image file, or null where this browser cannot decode it. */
async function imageSize(file) {
  if (!sizes.has(file)) {
    sizes.set(file, createImageBitmap(file).then((bitmap) => {
      const size = [bitmap.width, bitmap.height];
      bitmap.close();
      return size;
    }).catch(() => null)); // not an image the browser reads: the service will say why
  }
  return sizes.get(file);
}

/** A counter per input: true while ``token`` is still its latest read. */
function latest(id, token) {
  return state.reads[id] === token;
}

function nextRead(id) {
  state.reads[id] = (state.reads[id] || 0) + 1;
  return state.reads[id];
}

function describeFile(file, size) {
  return size
    ? `${file.name}: ${size[0]} × ${size[1]} pixels`
    : `${file.name}: not an image this browser can show`;
}

/** The chosen textures: their sizes read, the list of thumbnails (for an operation that
 * takes several), the box's hint and the block presets. */
async function renderTextures() {
  const files = [...$("texture").files];
  const token = nextRead("texture");
  const known = await Promise.all(files.map(imageSize));
  if (!latest("texture", token)) return;
  const many = several();
  textures.render(files, known, many);
  $("texture-info").textContent = textureInfo(files, known, many);
  // The presets fit every texture used: the smallest's shorter side.
  const used = (many ? known : known.slice(0, 1)).filter(Boolean);
  state.textureSize = used.length
    ? used.reduce((a, b) => (Math.min(...b) < Math.min(...a) ? b : a))
    : null;
  renderPresets();
  updateRequest();
}

function textureInfo(files, known, many) {
  if (!files.length) return many ? TEXTURES_HINT : TEXTURE_HINT;
  if (files.length === 1) return describeFile(files[0], known[0]);
  if (many) {
    const unreadable = files.filter((file, i) => !known[i]).map((file) => file.name);
    return `${files.length} textures, quilted together in this order; a weight says how ` +
      "much to prefer each (the same for all: no preference)." +
      (unreadable.length ? ` Not images this browser can show: ${unreadable.join(", ")}.` : "");
  }
  return `${describeFile(files[0], known[0])} (the first of the ${files.length} chosen: ` +
    "this operation takes one)";
}

/** A new image of a fill: painted on afresh, with the chosen mask file (if any) on it. */
async function paintOn(file) {
  await painter.setImage(file || null);
  if ($("mask").files[0]) await showMaskFile();
}

/** The chosen mask file: shown on the image to be painted on, or why it is not. */
async function showMaskFile() {
  const file = $("mask").files[0];
  const info = $("mask-file-info");
  if (!file) {
    info.textContent = info.dataset.empty;
    return;
  }
  const token = nextRead("mask");
  info.textContent = file.name;
  const problem = await painter.loadMask(file);
  if (!latest("mask", token)) return;
  info.textContent = problem ? `${file.name}: ${problem}` : `${file.name}: shown on the image`;
}

/** The target, silhouette and normal-map boxes: the chosen file's size, and a word where the
 * silhouette or normal map is not the target's size (the service refuses those). */
async function describeMatteInputs() {
  const token = nextRead("matte");
  const files = Object.fromEntries(
    ["target", "silhouette", "normals"].map((id) => [id, $(id).files[0] || null]));
  const known = Object.fromEntries(await Promise.all(Object.entries(files).map(
    async ([id, file]) => [id, file ? await imageSize(file) : null])));
  if (!latest("matte", token)) return;
  const target = known.target;
  for (const [id, file] of Object.entries(files)) {
    const info = $(`${id}-info`);
    if (!file) {
      info.textContent = id === "target" ? targetHint() : info.dataset.empty;
      continue;
    }
    let text = describeFile(file, known[id]);
    const size = known[id];
    if (id !== "target" && target && size && (size[0] !== target[0] || size[1] !== target[1])) {
      text += `, not the target's ${target[0]} × ${target[1]}`;
    }
    info.textContent = text;
  }
}

/** The layers of a matting in their order (bottom first), each movable and removable. */
async function renderLayers(focus = null) {
  const input = $("layers");
  const files = [...input.files];
  const token = nextRead("layers");
  const trimaps = files.map((file) => layerTrimaps.get(file) || null);
  const [known, kinds, trimapSizes] = await Promise.all([
    Promise.all(files.map(imageSize)),
    Promise.all(files.map(alphaOf)),
    Promise.all(trimaps.map((trimap) => (trimap ? imageSize(trimap) : null))),
  ]);
  if (!latest("layers", token)) return;
  state.layerSize = known[0] || null;
  const list = $("layers-order");
  list.replaceChildren(...files.map((file, index) => {
    const item = document.createElement("li");
    const name = document.createElement("span");
    name.className = "layer-name";
    const where = files.length > 1 && index === 0 ? ", bottom"
      : files.length > 1 && index === files.length - 1 ? ", top" : "";
    const size = known[index] ? `${known[index][0]} × ${known[index][1]}` : "not readable here";
    name.textContent = `${file.name} (${size}${where})`;
    item.append(name);
    for (const [action, text, label, disabled] of [
      ["earlier", "↑", `Move ${file.name} earlier (towards the bottom)`, index === 0],
      ["later", "↓", `Move ${file.name} later (towards the top)`, index === files.length - 1],
      ["remove", "✕", `Remove ${file.name}`, false],
    ]) {
      item.append(listButton("layer", action, text, label, disabled, index));
    }
    item.append(layerTrimapRow(file, index, kinds[index], known[index], trimapSizes[index]));
    return item;
  }));
  list.hidden = !files.length;
  if (focus?.action === "trimap") {
    const row = list.querySelector(`.layer-trimap[data-index="${focus.index}"]`);
    (row?.querySelector("button, input") || input).focus();
  } else if (focus) {
    const buttons = [...list.querySelectorAll("button:not(:disabled)")];
    const same = buttons.find((b) => b.dataset.index === String(focus.index) &&
      b.dataset.action === focus.action);
    const near = buttons.find((b) => b.dataset.index === String(focus.index));
    (same || near || buttons.at(-1) || input).focus();
  }
  renderPresets();
}

/**
 * Under a layer: its trimap, chosen with "Trimap…" (a file input in a label), named with its
 * size (and a word where it is not the layer's), and taken off with ✕. A layer with alpha of
 * its own needs none: it says so instead.
 */
function layerTrimapRow(file, index, kind, size, trimapSize) {
  const row = document.createElement("div");
  row.className = "layer-trimap";
  row.dataset.index = String(index);
  const trimap = layerTrimaps.get(file);
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
function chooseLayerTrimap(event) {
  const chooser = event.target.closest("input.layer-trimap-file");
  if (!chooser) return;
  const index = Number(chooser.dataset.index);
  const layer = $("layers").files[index];
  const trimap = chooser.files[0];
  if (!layer || !trimap) return;
  layerTrimaps.set(layer, trimap);
  renderLayers({ index, action: "trimap" });
}

/** A click on a layer's button: move it one place, take it out, or take its trimap off. */
function editLayers(event) {
  const off = event.target.closest("button.layer-untrimap");
  if (off) {
    const index = Number(off.dataset.index);
    const layer = $("layers").files[index];
    if (layer) layerTrimaps.delete(layer);
    renderLayers({ index, action: "trimap" });
    return;
  }
  const focus = editFiles($("layers"), event);
  if (!focus) return;
  renderLayers(focus);
  updateRequest();
}

/** Drag-and-drop onto each image box: the dropped files go into its file input. */
function enableDrops() {
  for (const drop of document.querySelectorAll(".drop")) {
    const input = $(drop.dataset.input);
    drop.addEventListener("dragover", (event) => {
      event.preventDefault();
      drop.classList.add("over");
    });
    drop.addEventListener("dragleave", () => drop.classList.remove("over"));
    drop.addEventListener("drop", (event) => {
      event.preventDefault();
      drop.classList.remove("over");
      const files = event.dataTransfer?.files;
      if (!files || !files.length) return;
      const chosen = new DataTransfer();
      for (const file of input.multiple ? files : [files[0]]) chosen.items.add(file);
      input.files = chosen.files;
      input.dispatchEvent(new Event("change", { bubbles: true }));
    });
  }
}

// --- running a job ---------------------------------------------------------------------------

/** A client-side refusal of the form, with the control to fix (focused when shown). */
function missing(id, message) {
  const error = new Error(message);
  error.input = $(id);
  return error;
}

function matteBody(options) {
  const target = $("target").files[0];
  if (!target) throw missing("target", "choose a target image: the picture of the object");
  const silhouette = $("silhouette").files[0];
  if (!silhouette) {
    throw missing("silhouette",
      "choose a silhouette: the target's size, white where the surface is");
  }
  const layers = [...$("layers").files];
  if (!layers.length) throw missing("layers", "choose one layer or more: the textures to lay");
  const body = new FormData();
  body.append("target", target);
  body.append("silhouette", silhouette);
  for (const layer of layers) body.append("layer", layer); // bottom first
  // A trimap per layer once one has one, in the layers' order: an empty part for the others.
  const trimaps = layers.map((layer) => layerTrimaps.get(layer) || null);
  if (trimaps.some(Boolean)) {
    for (const trimap of trimaps) {
      if (trimap) body.append("trimap", trimap, trimap.name);
      else body.append("trimap", new Blob([]), "none");
    }
  }
  const normals = $("normals").files[0];
  if (normals) body.append("normals", normals);
  body.append("options", JSON.stringify(options));
  return { body, texture: target };
}

/** The mask of a fill: the chosen file as it is when it was not painted on (so that the
 * service reads its own pixels), else the painted one (a promise of its PNG). */
function fillMask() {
  const file = $("mask").files[0];
  if (file && !painter.edited) return file;
  if (painter.empty) {
    throw missing("mask", "paint over the area to fill on the image, or choose a mask");
  }
  return painter.png();
}

/** A fill's request: checked at once; its body a promise (the painted mask is encoded while
 * the page already says it is submitting). */
function fillBody(options) {
  const image = $("texture").files[0];
  if (!image) throw missing("texture", "choose an image first");
  const mask = fillMask();
  const texture = $("fill-texture").files[0];
  const companions = [...$("companions").files];
  const body = Promise.resolve(mask).then((blob) => {
    const form = new FormData();
    form.append("image", image);
    form.append("mask", blob, blob.name || "mask.png");
    if (texture) form.append("texture", texture);
    for (const companion of companions) form.append("companion", companion);
    form.append("options", JSON.stringify(options));
    return form;
  });
  return { body, texture: image };
}

function extendBody(options) {
  const image = $("texture").files[0];
  if (!image) throw missing("texture", "choose an image first");
  const top = state.options?.input("top");
  if (top && !SIDES.some((side) => options[side] > 0)) {
    const error = new Error("give the pixels to add on one side at least (top, bottom, " +
      "left or right)");
    error.input = top;
    throw error;
  }
  const body = new FormData();
  body.append("image", image);
  for (const companion of $("companions").files) body.append("companion", companion);
  body.append("options", JSON.stringify(options));
  return { body, texture: image };
}

/** A Wang tile set's request: its texture parts, in order, and the options. */
function wangBody(options) {
  const files = [...$("texture").files];
  if (!files.length) throw missing("texture", "choose a texture first (or several)");
  const body = new FormData();
  for (const file of files) body.append("texture", file);
  body.append("options", JSON.stringify(options));
  return { body, texture: files[0] };
}

/** ``{body, texture}`` of the operation's request (body: FormData, or a promise of it for a
 * fill or painted scribbles); throws, with the control to fix, on what is missing. */
function requestBody(op, options) {
  if (op === "matte") return matteBody(options);
  if (op === "fill") return fillBody(options);
  if (op === "extend") return extendBody(options);
  if (op === "wang") return wangBody(options);
  const files = [...$("texture").files];
  const texture = files[0];
  if (!texture) {
    throw missing("texture", `choose ${op === "tile" ? "an image" : "a texture"} first`);
  }
  const body = new FormData();
  if (op === "tile") {
    body.append("image", texture);
  } else {
    // Several examples: one texture part each, in the order shown.
    for (const file of several(op) ? files : [texture]) body.append("texture", file);
  }
  if (op === "transfer") {
    const target = $("target").files[0];
    if (!target) throw new Error("choose a target image for the transfer");
    body.append("target", target);
  }
  if (op !== "tile") {
    const mask = $("source-mask").files[0];
    if (mask) body.append("source_mask", mask);
    for (const companion of $("companions").files) body.append("companion", companion);
  }
  body.append("options", JSON.stringify(options));
  // An opaque photo with a trimap or scribbles: its alpha is extracted, then quilted (with
  // several textures, the first's; an empty part for each of the others).
  const parts = op === "synthesize" ? alpha.parts(files.length) : [];
  if (!parts.length) return { body, texture };
  const withAlpha = Promise.all(parts.map(([, blob]) => blob)).then((blobs) => {
    parts.forEach(([name, , filename], i) => body.append(name, blobs[i], filename));
    return body;
  });
  return { body: withAlpha, texture };
}

/** Show a refusal of the form and focus the control to fix (opening "More options"). */
function refuse(error) {
  showError(error);
  const details = error.input?.closest("details");
  if (details) details.open = true;
  error.input?.focus();
}

async function run(event) {
  event.preventDefault();
  if (state.job) return;
  showError(null);
  const op = operation();
  const key = $("api-key").value.trim();
  let body, texture, seed;
  try {
    const options = optionValues();
    ({ body, texture } = requestBody(op, options));
    seed = Number.isInteger(options.seed) ? options.seed : 0; // a Wang preview's first
  } catch (error) {
    refuse(error);
    return;
  }
  await perform(key, seed, (signal) => (op === "tile"
    ? runTile(body, texture, key, signal)
    : runJob(op, body, texture, key, signal)));
}

/** Run ``work(signal)`` as the page's one job: the result cleared first, the controls busy
 * while it runs, Cancel aborting it, its failure shown. */
async function perform(key, seed, work) {
  viewer.clear();
  preview.clear();
  $("job-id").textContent = "";
  const controller = new AbortController();
  state.job = { id: null, key, controller, seed };
  setRunning(true);
  try {
    await work(controller.signal);
  } catch (error) {
    if (error.name === "AbortError") {
      setStatus("cancelled");
    } else {
      showError(error);
      setStatus(`failed: ${error.message}`);
    }
  } finally {
    state.job = null;
    setRunning(false);
  }
}

async function runTile(body, texture, key, signal) {
  setStatus("running: tile");
  setProgress(null);
  const started = performance.now();
  const response = await request("/tile", { method: "POST", body, key, signal });
  const result = await response.blob();
  setProgress(1);
  setStatus("done");
  await viewer.show({
    result,
    input: texture,
    // The service's name for it (<image>-tile.png), as a plain request would save it.
    resultName: downloadName(response, "quilting-tile.png"),
    layout: null,
    companions: [],
    loadSeams: null,
    noSeams: "Making an image tileable has no block seams: judge it in the 3×3 view.",
    stats: [["time", `${((performance.now() - started) / 1000).toFixed(2)} s`]],
  });
}

async function runJob(op, body, texture, key, signal) {
  setStatus("submitting");
  setProgress(0);
  // wait=0: answered at once with the job; its progress then comes from the event stream.
  const response = await request(`${OPERATIONS[op].path}?wait=0`, {
    method: "POST", body: await body, key, signal,
  });
  const id = response.headers.get("X-Job-Id");
  if (!id) throw new Error("the service answered without a job id");
  const snapshot = await followed(id, key, signal);
  if (!snapshot) return;
  await showJob(op, snapshot, texture, key, signal);
  setStatus("done");
}

/** Follow the job ``id`` to its end: its final status document once done, null when it was
 * cancelled (so said); throws the problem of a failed one. */
async function followed(id, key, signal) {
  state.job.id = id;
  $("job-id").textContent = id;
  setStatus("queued");
  const snapshot = await follow(id, key, signal);
  $("cancel").disabled = true;
  if (snapshot.status === "cancelled") {
    setStatus("cancelled");
    return null;
  }
  if (snapshot.status === "failed") {
    const problem = snapshot.error || {};
    throw new ApiError(0, problem.code || "job_failed", problem.detail || "the job failed");
  }
  setProgress(1);
  $("cancel").disabled = true; // nothing left to cancel
  setStatus("fetching the result");
  return snapshot;
}

/** "Extract alpha": POST /extract-alpha of the photo and its trimap or scribbles, followed as
 * a job; the RGBA texture shown as a result (over the checkerboard, the photo beside it) with
 * what the service says of the extraction (its Quilting-Extracted header). */
async function extract() {
  if (state.job) return;
  showError(null);
  const key = $("api-key").value.trim();
  let body, photo;
  try {
    ({ body, photo } = alpha.extractRequest());
  } catch (error) {
    refuse(error);
    return;
  }
  await perform(key, 0, async (signal) => {
    setStatus("submitting");
    setProgress(0);
    // wait=0: answered at once with the job; its progress then comes from the event stream.
    const response = await request("/extract-alpha?wait=0", {
      method: "POST", body: await body, key, signal,
    });
    let answer = response; // 200: the RGBA texture itself (a job already done)
    if (response.status === 202) {
      const id = response.headers.get("X-Job-Id");
      if (!id) throw new Error("the service answered without a job id");
      const snapshot = await followed(id, key, signal);
      if (!snapshot) return;
      answer = await request(snapshot.result || `/jobs/${id}/result`, { key, signal });
    }
    const result = await answer.blob();
    const extracted = summariesOf(answer.headers.get("Quilting-Extracted"));
    setProgress(1);
    alpha.showSummary(summaryLine(extracted) || "Extracted.");
    await viewer.show({
      result,
      resultName: downloadName(answer, `${photo.name.replace(/\.[^.]*$/, "")}-alpha.png`),
      input: photo,
      inputLabel: "Photo",
      resultLabel: "Extracted RGBA",
      view: "side",
      layout: null,
      companions: [],
      loadSeams: null,
      noSeams: "An extracted alpha has no block seams: compare it with the photo side by side.",
      stats: summaryStats(extracted),
    });
    setStatus("done");
  });
}

function onProgress(data) {
  if (typeof data.progress === "number") setProgress(data.progress);
  if (data.status === "queued") setStatus("queued");
  else if (data.status === "running") setStatus(`running: ${data.stage || "working"}`);
}

/** The job's final status document: from the event stream, else by polling. */
async function follow(id, key, signal) {
  try {
    const final = await followEvents(`/jobs/${id}/events`, {
      key, signal, onEvent: (name, data) => onProgress(data),
    });
    if (final && FINAL.has(final.data.status)) return final.data;
  } catch (error) {
    if (error.name === "AbortError" || error instanceof ApiError && error.status) throw error;
    // The stream broke (a proxy, a network blip): the status document still answers.
  }
  for (;;) {
    const snapshot = await getJson(`/jobs/${id}`, { key, signal });
    onProgress(snapshot);
    if (FINAL.has(snapshot.status)) return snapshot;
    await new Promise((resolve) => setTimeout(resolve, POLL_MS));
  }
}

/** A stat's value as text, or null for one the page does not show. */
function statText(name, value) {
  const number = (v) => (Number.isInteger(v) ? String(v) : v.toPrecision(4));
  if (typeof value === "number") return number(value);
  if (Array.isArray(value) && value.length && value.every((v) => typeof v === "number")) {
    if ((name.endsWith("_size") || name === "atlas") && value.length === 2) {
      return `${value[0]} × ${value[1]}`; // a width and a height
    }
    return value.map((v) => (Number.isInteger(v) ? String(v) : v.toFixed(3))).join(", ");
  }
  return null;
}

async function showJob(op, snapshot, texture, key, signal) {
  const id = snapshot.id;
  const operation = OPERATIONS[op] || {};
  const companionNames = snapshot.companions || [];
  // Each file comes with the name the service gives it (Content-Disposition): the downloads
  // are saved as a plain GET of the same URL would be.
  const get = (path, fallback) => getFile(path, fallback, { key, signal });
  const [result, layout, manifest, ...companions] = await Promise.all([
    get(snapshot.result || `/jobs/${id}/result`, `quilting-${id}.png`),
    // None of a matting; a Wang tile set's layout is its manifest, offered as such below.
    snapshot.layout && !operation.wang
      ? get(snapshot.layout, `quilting-${id}-layout.json`) : null,
    // A Wang tile set's manifest: the tiles' places in the atlas and their edge colours.
    operation.wang
      ? get(snapshot.manifest || `/jobs/${id}/manifest`, `quilting-${id}-manifest.json`)
      : null,
    ...companionNames.map((name) => get(
      `/jobs/${id}/result/${encodeURIComponent(name)}`, `quilting-${id}-${name}.png`)),
  ]);
  const stats = [
    ["size", `${snapshot.width} × ${snapshot.height}`],
    ["backend", snapshot.backend + (snapshot.renderer ? ` (${snapshot.renderer})` : "")],
  ];
  if (snapshot.timings?.total !== undefined) {
    stats.push(["time", `${snapshot.timings.total.toFixed(2)} s`]);
  }
  for (const [name, value] of Object.entries(snapshot.stats || {})) {
    const text = statText(name, value);
    if (text !== null) stats.push([STAT_LABELS[name] || name.replaceAll("_", " "), text]);
  }
  // The photos whose alpha was extracted first (Quilting-Extracted, stats.extracted).
  const extracted = summariesOf(snapshot.stats?.extracted);
  if (extracted.length) {
    const of = { noun: op === "matte" ? "layer" : "texture",
      count: snapshot.stats.extracted.length };
    stats.push(...summaryStats(extracted, of));
    if (op === "synthesize") alpha.showSummary(summaryLine(extracted, of));
  }
  await viewer.show({
    result: result.blob,
    resultName: result.name,
    downloadLabel: operation.download,
    input: texture,
    inputLabel: operation.input,
    resultLabel: operation.result,
    view: operation.view,
    layout: layout?.blob ?? null,
    layoutName: layout?.name,
    companions: companionNames.map((name, i) => [
      name, companions[i].blob, operation.companions?.[name], companions[i].name]),
    // The seams are drawn from the layout: none without one (nor on a Wang atlas).
    loadSeams: layout ? () => getBlob(`/jobs/${id}/seams`, { key }) : null,
    noSeams: operation.noSeams || "This result has no block layout, so no seams to show.",
    stats,
  });
  if (manifest) { // a Wang tile set: its atlas is shown; now its manifest and preview
    let set;
    try {
      set = JSON.parse(await manifest.blob.text());
    } catch (error) {
      throw new Error(`the manifest is not JSON: ${error.message}`);
    }
    await preview.show({
      atlas: result.blob, manifest: set, manifestBlob: manifest.blob,
      manifestName: manifest.name, seed: state.job.seed,
    });
  }
}

async function cancel() {
  const job = state.job;
  if (!job) return;
  $("cancel").disabled = true;
  setStatus("cancelling");
  if (!job.id) {
    job.controller.abort(); // not submitted yet, or a tile request: stop waiting for it
    return;
  }
  try {
    await request(`/jobs/${job.id}`, { method: "DELETE", key: job.key });
    // The event stream now delivers the job's final "cancelled" event.
  } catch (error) {
    if (error instanceof ApiError && error.code === "job_finished") return; // too late: done
    showError(error);
    $("cancel").disabled = false;
  }
}

// --- start -----------------------------------------------------------------------------------

async function start() {
  const form = $("job-form");
  form.addEventListener("submit", run);
  form.addEventListener("input", updateRequest);
  form.addEventListener("change", updateRequest);
  $("cancel").addEventListener("click", cancel);
  for (const radio of document.querySelectorAll('input[name="operation"]')) {
    radio.addEventListener("change", renderOptions);
  }
  $("texture").addEventListener("change", () => renderTextures());
  $("texture").addEventListener("change", () => alpha.setTextures([...$("texture").files]));
  $("extract").addEventListener("click", extract);
  form.addEventListener("change", (event) => {
    if (event.target.id === "opt-matting") alpha.setMethod(event.target.value);
  });
  for (const id of ["target", "silhouette", "normals"]) {
    $(`${id}-info`).dataset.empty = $(`${id}-info`).textContent;
    $(id).addEventListener("change", describeMatteInputs);
  }
  $("layers").addEventListener("change", () => renderLayers());
  $("texture").addEventListener("change", (event) => paintOn(event.target.files[0]));
  $("mask-file-info").dataset.empty = $("mask-file-info").textContent;
  $("mask").addEventListener("change", showMaskFile);
  $("layers-order").addEventListener("click", editLayers);
  $("layers-order").addEventListener("change", chooseLayerTrimap);
  const key = $("api-key");
  key.value = sessionStorage.getItem("quilting-api-key") || "";
  key.addEventListener("change", () => sessionStorage.setItem("quilting-api-key", key.value));
  enableDrops();
  try {
    const spec = await getJson("/openapi.json");
    state.schemas = spec.components?.schemas || {};
  } catch (error) {
    showError(new Error(`the options could not be loaded: ${error.message}`));
  }
  alpha.setSchemas(state.schemas);
  renderOptions();
  form.dataset.ready = "true";
}

start();
