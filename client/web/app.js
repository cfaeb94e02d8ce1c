// The page: pick an operation and images, set options, run a job on the service, follow its
// progress, cancel it, and show what came back. Talks to the HTTP API only (api.js).

import { ApiError, followEvents, getBlob, getJson, request } from "./api.js";
import { PRESETS, buildOptions, presetBlock } from "./options.js";
import { Viewer } from "./viewer.js";

const $ = (id) => document.getElementById(id);

const OPERATIONS = {
  synthesize: {
    path: "/synthesize",
    hint: "A larger texture of any size from the sample.",
    textureLabel: "Texture",
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
};

const FINAL = new Set(["done", "failed", "cancelled"]);
const POLL_MS = 500;

const state = {
  schemas: {},
  options: null,
  job: null, // {id, key, controller} of the job being followed
  textureSize: null, // [width, height] of the chosen texture
};
const viewer = new Viewer();

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
  $("cancel").disabled = !running;
  $("job-form").setAttribute("aria-busy", String(running));
}

// --- the form --------------------------------------------------------------------------------

function operation() {
  return document.querySelector('input[name="operation"]:checked').value;
}

function renderOptions() {
  const op = operation();
  state.options = buildOptions(state.schemas, op, $("main-options"), $("extra-options"));
  $("operation-hint").textContent = OPERATIONS[op].hint;
  $("texture-label").textContent = OPERATIONS[op].textureLabel;
  for (const drop of document.querySelectorAll(".drop[data-for]")) {
    drop.hidden = !drop.dataset.for.split(" ").includes(op);
  }
  renderPresets();
  updateRequest();
}

function renderPresets() {
  const box = $("presets");
  for (const old of box.querySelectorAll("button")) old.remove();
  const block = state.options?.input("block");
  box.hidden = !block;
  if (!block) return;
  for (const preset of PRESETS) {
    const button = document.createElement("button");
    button.type = "button";
    button.className = "preset";
    const size = state.textureSize
      ? presetBlock(preset.fraction, ...state.textureSize)
      : null;
    button.textContent = size
      ? `${preset.name} (${preset.label} → ${size} px)`
      : `${preset.name} (${preset.label})`;
    button.disabled = !size;
    button.title = `Block side ${preset.label} of the texture's shorter side`;
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

async function readTextureSize(file) {
  state.textureSize = null;
  if (file) {
    try {
      const bitmap = await createImageBitmap(file);
      state.textureSize = [bitmap.width, bitmap.height];
      bitmap.close();
    } catch {
      // Not an image the browser reads: the service will say what is wrong with it.
    }
  }
  const info = $("texture-info");
  info.textContent = !file
    ? "PNG or JPEG. Drop a file here or choose one."
    : state.textureSize
      ? `${file.name}: ${state.textureSize[0]} × ${state.textureSize[1]} pixels`
      : `${file.name}: not an image this browser can show`;
  renderPresets();
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

function requestBody(op, options) {
  const texture = $("texture").files[0];
  if (!texture) throw new Error(`choose ${op === "tile" ? "an image" : "a texture"} first`);
  const body = new FormData();
  body.append(op === "tile" ? "image" : "texture", texture);
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
  return { body, texture };
}

async function run(event) {
  event.preventDefault();
  if (state.job) return;
  showError(null);
  const op = operation();
  const key = $("api-key").value.trim();
  let body, texture;
  try {
    const options = optionValues();
    ({ body, texture } = requestBody(op, options));
  } catch (error) {
    showError(error);
    return;
  }
  viewer.clear();
  $("job-id").textContent = "";
  const controller = new AbortController();
  state.job = { id: null, key, controller };
  setRunning(true);
  try {
    if (op === "tile") await runTile(body, texture, key, controller.signal);
    else await runJob(op, body, texture, key, controller.signal);
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
  const result = await (await request("/tile", { method: "POST", body, key, signal })).blob();
  setProgress(1);
  setStatus("done");
  await viewer.show({
    result,
    input: texture,
    name: texture.name.replace(/\.[^.]*$/, "") + "-tileable",
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
    method: "POST", body, key, signal,
  });
  const id = response.headers.get("X-Job-Id");
  if (!id) throw new Error("the service answered without a job id");
  state.job.id = id;
  $("job-id").textContent = id;
  setStatus("queued");
  const snapshot = await follow(id, key, signal);
  $("cancel").disabled = true;
  if (snapshot.status === "cancelled") {
    setStatus("cancelled");
    return;
  }
  if (snapshot.status === "failed") {
    const problem = snapshot.error || {};
    throw new ApiError(0, problem.code || "job_failed", problem.detail || "the job failed");
  }
  setProgress(1);
  $("cancel").disabled = true; // nothing left to cancel
  setStatus("fetching the result");
  await showJob(snapshot, texture, key, signal);
  setStatus("done");
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

async function showJob(snapshot, texture, key, signal) {
  const id = snapshot.id;
  const get = (path) => getBlob(path, { key, signal });
  const [result, layout, ...companions] = await Promise.all([
    get(snapshot.result),
    get(snapshot.layout),
    ...snapshot.companions.map((name) => get(`/jobs/${id}/result/${encodeURIComponent(name)}`)),
  ]);
  const stats = [
    ["size", `${snapshot.width} × ${snapshot.height}`],
    ["backend", snapshot.backend + (snapshot.renderer ? ` (${snapshot.renderer})` : "")],
  ];
  if (snapshot.timings?.total !== undefined) {
    stats.push(["time", `${snapshot.timings.total.toFixed(2)} s`]);
  }
  for (const [name, value] of Object.entries(snapshot.stats || {})) {
    if (typeof value === "number") stats.push([name.replaceAll("_", " "), value.toPrecision(4)]);
  }
  await viewer.show({
    result,
    input: texture,
    name: `quilting-${id}`,
    layout,
    companions: snapshot.companions.map((name, i) => [name, companions[i]]),
    loadSeams: () => getBlob(`/jobs/${id}/seams`, { key }),
    stats,
  });
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
  $("texture").addEventListener("change", (event) => readTextureSize(event.target.files[0]));
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
  renderOptions();
  form.dataset.ready = "true";
}

start();
