// The request of each operation: the form's files and options as the multipart body the
// service's endpoint takes, checked first, so that what is missing is said (with the control
// to fix) before anything is sent.

import { OPERATIONS } from "./operations.js";

const $ = (id) => document.getElementById(id);

/** The sides an extension adds pixels on (ExtendOptions). */
const SIDES = ["top", "bottom", "left", "right"];

/** A client-side refusal of the form, with the control to fix (focused when shown). */
export function missing(id, message) {
  const error = new Error(message);
  error.input = $(id);
  return error;
}

function matteBody(options, page) {
  const target = $("target").files[0];
  if (!target) throw missing("target", "choose a target image: the picture of the object");
  const silhouette = $("silhouette").files[0];
  if (!silhouette) {
    throw missing("silhouette",
      "choose a silhouette: the target's size, white where the surface is");
  }
  const files = [...$("layers").files];
  if (!files.length) throw missing("layers", "choose one layer or more: the textures to lay");
  const body = new FormData();
  body.append("target", target);
  body.append("silhouette", silhouette);
  for (const layer of files) body.append("layer", layer); // bottom first
  // A trimap per layer once one has one, in the layers' order: an empty part for the others.
  const trimaps = files.map((layer) => page.layers.trimapOf(layer));
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
function fillMask(page) {
  const file = $("mask").files[0];
  if (file && !page.painter.edited) return file;
  if (page.painter.empty) {
    throw missing("mask", "paint over the area to fill on the image, or choose a mask");
  }
  return page.painter.png();
}

/** A fill's request: checked at once; its body a promise (the painted mask is encoded while
 * the page already says it is submitting). */
function fillBody(options, page) {
  const image = $("texture").files[0];
  if (!image) throw missing("texture", "choose an image first");
  const mask = fillMask(page);
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

function extendBody(options, page) {
  const image = $("texture").files[0];
  if (!image) throw missing("texture", "choose an image first");
  const top = page.option("top");
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
function wangBody(options, page) {
  const files = [...$("texture").files];
  if (!files.length) throw missing("texture", "choose a texture first (or several)");
  const body = new FormData();
  for (const file of files) body.append("texture", file);
  body.append("options", JSON.stringify(options));
  return { body, texture: files[0] };
}

/**
 * ``{body, texture}`` of the operation ``op``'s request with ``options`` (body: FormData, or a
 * promise of it for a fill or painted scribbles; texture: the file shown beside the result);
 * throws, with the control to fix, on what is missing. ``page``: ``{layers, painter, alpha,
 * option(name)}``, the matting's layer list, the fill's mask painter, the alpha panel and the
 * options form's field of a name.
 */
export function requestBody(op, options, page) {
  if (op === "matte") return matteBody(options, page);
  if (op === "fill") return fillBody(options, page);
  if (op === "extend") return extendBody(options, page);
  if (op === "wang") return wangBody(options, page);
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
    for (const file of OPERATIONS[op].several ? files : [texture]) body.append("texture", file);
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
  const parts = op === "synthesize" ? page.alpha.parts(files.length) : [];
  if (!parts.length) return { body, texture };
  const withAlpha = Promise.all(parts.map(([, blob]) => blob)).then((blobs) => {
    parts.forEach(([name, , filename], i) => body.append(name, blobs[i], filename));
    return body;
  });
  return { body: withAlpha, texture };
}
