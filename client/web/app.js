// The page: pick an operation and images, set options, run a job on the service, follow its
// progress, cancel it, and show what came back. Talks to the HTTP API only (api.js).

import {
  ApiError, downloadName, followEvents, getFile, getJson, request, statusWords,
} from "./api.js";
import { AlphaPanel, summariesOf, summaryLine, summaryStats } from "./alpha.js";
import { BlockView } from "./blockview.js";
import { explainStats } from "./figures.js";
import { History, entryOf, sentIn } from "./history.js";
import {
  FilePreview, describeImage, enableDrops, enablePaste, imageSize, infoOf,
} from "./inputs.js";
import { LayerList } from "./layers.js";
import { MaskPainter } from "./mask.js";
import { OPERATIONS } from "./operations.js";
import { PRESETS, buildOptions, presetBlock } from "./options.js";
import { requestBody as bodyOf } from "./requests.js";
import { SizePresets } from "./sizes.js";
import { TextureList } from "./textures.js";
import { Variations, freshSeeds } from "./variations.js";
import { Viewer } from "./viewer.js";
import { WangPreview } from "./wang.js";

const $ = (id) => document.getElementById(id);

/** The texture box's hint with no file chosen: one texture, or one or more. */
const TEXTURE_HINT = "PNG or JPEG. Drop a file here or choose one.";
const TEXTURES_HINT = "PNG or JPEG, one or more (of the same channels). Drop files here or " +
  "choose them: several are quilted together.";

/** The target's hint outside a matting (in index.html). */
const TARGET_HINT = "The image to render in the texture; the output has its size.";

const FINAL = new Set(["done", "failed", "cancelled"]);
const POLL_MS = 500;

const state = {
  schemas: {},
  options: null,
  // The work under way (a Run, the variations, an extraction, showing a kept variation):
  // the ids of its jobs on the service (Cancel deletes each), the key they were sent with, the
  // controller that aborts its requests, its seed (null: none), and whether Cancel was pressed.
  job: null, // {ids, key, controller, seed, cancelled}
  body: null, // the request (FormData, or a promise of it) of the result to be shown next
  textureSize: null, // [width, height] of the chosen texture (the smallest of several)
  textureFile: null, // the File of that size
  reads: {}, // by input id: a counter, so that only the latest choice's sizes are shown
};
const viewer = new Viewer();
const painter = new MaskPainter();
const preview = new WangPreview();
const textures = new TextureList($("texture"), $("textures-order"));
const layers = new LayerList($("layers"), $("layers-order"), () => {
  renderPresets();
  updateRequest();
});
const outputSize = new SizePresets($("size-presets"), () => updateRequest());
const blockView = new BlockView($("block-view"));
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
// "Make 4 variations" beside Run, and its grid under the result (variations.js).
const variations = new Variations({ start: makeVariations, keep: keepVariation });
// Every result shown, kept for this tab (history.js): shown again, or its options reused.
const resultHistory = new History({ show: showStored, reuse });

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
  variations.setBusy(running);
  resultHistory.setBusy(running);
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
  outputSize.attach(state.options.input("width"), state.options.input("height"));
  renderTextures();
  $("operation-hint").textContent = OPERATIONS[op].hint;
  // Variations: of a job with a seed (every operation but a tile).
  variations.setAvailable(!OPERATIONS[op].direct && Boolean(state.options.input("seed")));
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
  if (!block) {
    blockView.setSource(null, null);
    return;
  }
  // The texture's box holds the image of a tile, fill or extension; a matting has layers.
  const many = several() && $("texture").files.length > 1;
  const source = OPERATIONS[operation()].presetsFrom ||
    (many ? "these textures" : "this texture");
  const layer = source === "the first layer";
  const sourceSize = layer ? layers.size : state.textureSize;
  blockView.setSource(layer ? layers.file : state.textureFile, sourceSize);
  blockView.setBlock(block.value.trim());
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
    // The preset's block drawn on the texture while it is pointed at or focused.
    for (const [name, side] of [["pointerenter", size], ["focus", size],
      ["pointerleave", null], ["blur", null]]) {
      button.addEventListener(name, () => blockView.preview(side));
    }
    box.append(button);
  }
}

/** The options object to send, shown as JSON under the form; throws on a bad field. */
function optionValues() {
  return state.options ? state.options.values() : {};
}

function updateRequest() {
  const block = state.options?.input("block");
  if (block) blockView.setBlock(block.value.trim());
  try {
    $("request-json").textContent = JSON.stringify(optionValues(), null, 2);
  } catch (error) {
    $("request-json").textContent = error.message;
  }
}

/** A counter per input: true while ``token`` is still its latest read. */
function latest(id, token) {
  return state.reads[id] === token;
}

function nextRead(id) {
  state.reads[id] = (state.reads[id] || 0) + 1;
  return state.reads[id];
}


/** The chosen textures: their sizes read, the list of thumbnails (for an operation that
 * takes several), the box's hint and the block presets. */
async function renderTextures() {
  const files = [...$("texture").files];
  const token = nextRead("texture");
  const [known, details] = await Promise.all([
    Promise.all(files.map(imageSize)), Promise.all(files.map(infoOf)),
  ]);
  if (!latest("texture", token)) return;
  const many = several();
  textures.render(files, known, many, details);
  $("texture-info").textContent = textureInfo(files, known, many, details);
  // The presets fit every texture used: the smallest's shorter side.
  const used = (many ? files : files.slice(0, 1)).map((file, i) => [file, known[i]])
    .filter(([, size]) => size);
  const smallest = used.length
    ? used.reduce((a, b) => (Math.min(...b[1]) < Math.min(...a[1]) ? b : a))
    : [null, null];
  [state.textureFile, state.textureSize] = smallest;
  outputSize.setTexture(state.textureSize);
  renderPresets();
  updateRequest();
}

function textureInfo(files, known, many, details) {
  if (!files.length) return many ? TEXTURES_HINT : TEXTURE_HINT;
  if (files.length === 1) return describeImage(files[0], known[0], details[0]);
  if (many) {
    const unreadable = files.filter((file, i) => !known[i]).map((file) => file.name);
    return `${files.length} textures, quilted together in this order; a weight says how ` +
      "much to prefer each (the same for all: no preference)." +
      (unreadable.length ? ` Not images this browser can show: ${unreadable.join(", ")}.` : "");
  }
  return `${describeImage(files[0], known[0], details[0])} (the first of the ${files.length} ` +
    "chosen: this operation takes one)";
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
  const read = (file) => Promise.all([imageSize(file), infoOf(file)]);
  const both = Object.fromEntries(await Promise.all(Object.entries(files).map(
    async ([id, file]) => [id, file ? await read(file) : [null, null]])));
  const known = Object.fromEntries(Object.entries(both).map(([id, [size]]) => [id, size]));
  if (!latest("matte", token)) return;
  const target = known.target;
  for (const [id, file] of Object.entries(files)) {
    const info = $(`${id}-info`);
    if (!file) {
      info.textContent = id === "target" ? targetHint() : info.dataset.empty;
      continue;
    }
    let text = describeImage(file, known[id], both[id][1]);
    const size = known[id];
    if (id !== "target" && target && size && (size[0] !== target[0] || size[1] !== target[1])) {
      text += `, not the target's ${target[0]} × ${target[1]}`;
    }
    info.textContent = text;
  }
}

// --- running a job ---------------------------------------------------------------------------

/** ``{body, texture}`` of the form's request for ``op`` with ``options`` (requests.js). */
function requestBody(op, options) {
  return bodyOf(op, options, {
    layers, painter, alpha, option: (name) => state.options?.input(name) ?? null,
  });
}

/** Show a refusal of the form and focus the control to fix (opening "More options"). */
function refuse(error) {
  showError(error);
  const details = error.input?.closest("details");
  if (details) details.open = true;
  error.input?.focus();
}

/** The seed a run of the form uses: the one sent, else the field's (its default, not sent);
 * null for an operation without one. */
function formSeed(options) {
  if (Number.isInteger(options.seed)) return options.seed;
  const value = Number(state.options?.input("seed")?.value.trim() || NaN);
  return Number.isInteger(value) ? value : null;
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
    state.sent = options;
    state.body = body;
    seed = formSeed(options); // a Wang preview's first
  } catch (error) {
    refuse(error);
    return;
  }
  await perform(key, seed, (signal) => (OPERATIONS[op].direct
    ? runTile(body, texture, key, signal)
    : runJob(op, body, texture, key, signal)));
}

/** "Make 4 variations": the request of Run four times, each with a fresh random seed, all
 * submitted at once and followed through :func:`submitJob`, each in its cell of the grid. */
async function makeVariations() {
  if (state.job) return;
  showError(null);
  const op = operation();
  const key = $("api-key").value.trim();
  let jobs;
  try {
    const options = optionValues();
    jobs = freshSeeds().map((seed) => {
      const sent = { ...options, seed };
      return { seed, options: sent, ...requestBody(op, sent) };
    });
  } catch (error) {
    refuse(error);
    return;
  }
  await perform(key, jobs[0].seed, async (signal) => {
    setStatus(`running ${jobs.length} variations`);
    setProgress(0);
    const submit = (body, { report, onJob }) => submitJob(OPERATIONS[op].path, body, {
      key, signal, report,
      onJob: (id) => {
        onJob(id);
        $("job-id").textContent = state.job.ids.join(", ");
      },
    });
    setStatus(await variations.run(op, jobs, { submit, key, signal, progress: setProgress }));
  });
}

/** "Keep this one": the variation's seed put in the form (and its options, when another
 * operation is chosen now), its job shown as a Run's result would be, and kept in the history. */
async function keepVariation(variation) {
  if (state.job) return;
  showError(null);
  const seed = operation() === variation.op ? state.options?.input("seed") : null;
  if (seed) {
    seed.value = String(variation.seed);
    seed.dispatchEvent(new Event("input", { bubbles: true }));
    seed.dispatchEvent(new Event("change", { bubbles: true }));
  } else {
    reuse(variation.op, variation.options);
  }
  state.sent = variation.options;
  state.body = variation.body;
  await perform(variation.key, variation.seed, async (signal) => {
    $("job-id").textContent = variation.snapshot.id;
    setStatus("fetching the result");
    await showJob(variation.op, variation.snapshot, variation.texture, variation.key, signal);
    setStatus("done");
  });
}

/** Select the operation ``op`` and set its form to ``options`` (an options object as sent;
 * the options it lacks go back to their defaults): "Use these options again". */
function reuse(op, options) {
  const radio = document.querySelector(`input[name="operation"][value="${CSS.escape(op)}"]`);
  if (!radio) return;
  if (!radio.checked) {
    radio.checked = true;
    renderOptions();
  }
  state.options.set(options);
  const matting = state.options.input("matting");
  if (matting) alpha.setMethod(matting.value);
  outputSize.setLock(outputSize.lock.checked); // a kept aspect is the new size's
  updateRequest();
}

/** A result of the history shown in the viewer in place of the one there. */
async function showStored(shown) {
  viewer.clear();
  preview.clear();
  $("job-id").textContent = "";
  await viewer.show(shown);
}

/** Show a result in the viewer (``shown``: viewer.show's arguments) and add it to this tab's
 * history with what was sent for it (``state.body``) and the work's seed. */
async function present(op, shown) {
  await viewer.show(shown);
  resultHistory.add(entryOf(op, shown, {
    sent: sentIn(state.body).catch(() => null),
    seed: state.job?.seed,
    width: viewer.width,
    height: viewer.height,
  }));
}

/** Run ``work(signal)`` as the page's one piece of work (its jobs in ``state.job.ids``): the
 * result cleared first, the controls busy while it runs, Cancel stopping it, its failure
 * shown. */
async function perform(key, seed, work) {
  viewer.clear();
  preview.clear();
  $("job-id").textContent = "";
  const controller = new AbortController();
  state.job = { ids: [], key, controller, seed, cancelled: false };
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
  await present("tile", {
    result,
    input: texture,
    // The service's name for it (<image>-tile.png), as a plain request would save it.
    resultName: downloadName(response, "quilting-tile.png"),
    layout: null,
    companions: [],
    loadSeams: null,
    noSeams: "Making an image tileable has no block seams: judge it in the 3×3 view.",
    view: "tiled",
    stats: [["time", `${((performance.now() - started) / 1000).toFixed(2)} s`]],
  });
}

async function runJob(op, body, texture, key, signal) {
  const snapshot = await followed(OPERATIONS[op].path, body, key, signal);
  if (!snapshot) return;
  await showJob(op, snapshot, texture, key, signal);
  setStatus("done");
}

/**
 * Submit a job and follow it to its end, the one path of every job of the page (a Run, an
 * extraction, each variation): ``body`` (a FormData, or a promise of it) POSTed to ``path``
 * with wait=0, answered at once with the job; its id added to ``state.job.ids`` (Cancel
 * deletes each) and given to ``onJob(id)``; its progress, from the event stream, to
 * ``report(data)``. Resolves to its final status document, null when it was cancelled;
 * throws the problem of a failed one.
 */
async function submitJob(path, body, { key, signal, report = onProgress, onJob = () => {} }) {
  const response = await request(`${path}?wait=0`, {
    method: "POST", body: await body, key, signal,
  });
  const id = response.headers.get("X-Job-Id");
  if (!id) throw new Error("the service answered without a job id");
  const job = state.job;
  job.ids.push(id);
  if (job.cancelled) cancelJob(id, key); // Cancel was pressed while it was on its way
  onJob(id);
  const snapshot = await follow(id, key, signal, report);
  if (snapshot.status === "cancelled") return null;
  if (snapshot.status === "failed") {
    const problem = snapshot.error || {};
    throw new ApiError(0, problem.code || "job_failed", problem.detail || "the job failed");
  }
  return snapshot;
}

/** The page's one job (a Run, an extraction) through :func:`submitJob`, its id and progress
 * shown on the form: its final status document once done, null when cancelled (so said). */
async function followed(path, body, key, signal) {
  setStatus("submitting");
  setProgress(0);
  const snapshot = await submitJob(path, body, {
    key,
    signal,
    onJob: (id) => {
      $("job-id").textContent = id;
      setStatus("queued");
    },
  });
  $("cancel").disabled = true; // nothing left to cancel
  if (!snapshot) {
    setStatus("cancelled");
    return null;
  }
  setProgress(1);
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
  state.body = body;
  await perform(key, null, async (signal) => {
    const snapshot = await followed("/extract-alpha", body, key, signal);
    if (!snapshot) return;
    const answer = await request(snapshot.result || `/jobs/${snapshot.id}/result`,
      { key, signal });
    const result = await answer.blob();
    const extracted = summariesOf(answer.headers.get("Quilting-Extracted"));
    setProgress(1);
    alpha.showSummary(summaryLine(extracted) || "Extracted.");
    await present("extract", {
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

/** A status event of the page's one job, on the form's progress bar and status line. */
function onProgress(data) {
  if (typeof data.progress === "number") setProgress(data.progress);
  const words = statusWords(data);
  if (words) setStatus(words);
}

/** The job's final status document: from the event stream, else by polling; each status
 * event (or document) on the way given to ``report(data)``. */
async function follow(id, key, signal, report = onProgress) {
  try {
    const final = await followEvents(`/jobs/${id}/events`, {
      key, signal, onEvent: (name, data) => report(data),
    });
    if (final && FINAL.has(final.data.status)) return final.data;
  } catch (error) {
    if (error.name === "AbortError" || error instanceof ApiError && error.status) throw error;
    // The stream broke (a proxy, a network blip): the status document still answers.
  }
  for (;;) {
    const snapshot = await getJson(`/jobs/${id}`, { key, signal });
    report(snapshot);
    if (FINAL.has(snapshot.status)) return snapshot;
    await new Promise((resolve) => setTimeout(resolve, POLL_MS));
  }
}

/** What a job's blocks came from, as its figures name it ("12 % of the texture"). */
function sourceWords(op) {
  if (op === "fill" || op === "extend") {
    return op === "fill" && $("fill-texture").files.length ? "the texture" : "the image";
  }
  return several(op) && $("texture").files.length > 1 ? "the textures together" : "the texture";
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
  stats.push(...explainStats(snapshot.stats, {
    what: sourceWords(op), width: snapshot.width, height: snapshot.height,
  }));
  // The photos whose alpha was extracted first (Quilting-Extracted, stats.extracted).
  const extracted = summariesOf(snapshot.stats?.extracted);
  if (extracted.length) {
    const of = { noun: op === "matte" ? "layer" : "texture",
      count: snapshot.stats.extracted.length };
    stats.push(...summaryStats(extracted, of));
    if (op === "synthesize") alpha.showSummary(summaryLine(extracted, of));
  }
  await present(op, {
    result: result.blob,
    resultName: result.name,
    downloadLabel: operation.download,
    input: texture,
    inputLabel: operation.input,
    resultLabel: operation.result,
    // A tileable result is judged repeated: the 3×3 view shows its edges meet.
    view: operation.view || (state.sent?.tileable ? "tiled" : undefined),
    layout: layout?.blob ?? null,
    layoutName: layout?.name,
    companions: companionNames.map((name, i) => [
      name, companions[i].blob, operation.companions?.[name], companions[i].name]),
    // The seams are drawn from the layout: none without one (nor on a Wang atlas).
    loadSeams: layout
      ? () => getFile(`/jobs/${id}/seams`, `quilting-${id}-seams.png`, { key }) : null,
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
      manifestName: manifest.name, seed: state.job?.seed ?? 0,
    });
  }
}

/** DELETE /jobs/{id}: its event stream then ends with "cancelled". False, the problem
 * shown, where the service refused (a job already over is no problem: too late, done). */
async function cancelJob(id, key) {
  try {
    await request(`/jobs/${id}`, { method: "DELETE", key });
    return true;
  } catch (error) {
    if (error instanceof ApiError && error.code === "job_finished") return true;
    showError(error);
    return false;
  }
}

/** Cancel: every job of the work under way deleted (a variation still on its way as soon
 * as its id comes), or, with none submitted yet, its requests aborted. */
async function cancel() {
  const job = state.job;
  if (!job) return;
  $("cancel").disabled = true;
  setStatus("cancelling");
  job.cancelled = true;
  if (!job.ids.length) {
    job.controller.abort(); // not submitted yet, or a tile request: stop waiting for it
    return;
  }
  const asked = await Promise.all(job.ids.map((id) => cancelJob(id, job.key)));
  if (asked.includes(false) && state.job === job) $("cancel").disabled = false;
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
  $("texture").addEventListener("change", (event) => paintOn(event.target.files[0]));
  $("mask-file-info").dataset.empty = $("mask-file-info").textContent;
  $("mask").addEventListener("change", showMaskFile);
  const key = $("api-key");
  key.value = sessionStorage.getItem("quilting-api-key") || "";
  key.addEventListener("change", () => sessionStorage.setItem("quilting-api-key", key.value));
  enableDrops();
  enablePaste(setStatus);
  // The boxes without a list of their own show what was chosen in them as thumbnails.
  for (const drop of document.querySelectorAll(".drop[data-input]")) {
    if (!["texture", "layers"].includes(drop.dataset.input)) {
      new FilePreview($(drop.dataset.input), drop); // eslint-disable-line no-new
    }
  }
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
