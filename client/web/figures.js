// A job's figures in words: each stat the service reports (GET /jobs/{id}, "stats") as a
// label, its value with its unit, and one sentence on what it means, so that "largest_copy
// 0.1227" reads "largest piece copied whole: 12 % of the texture".

const number = (v) => (Number.isInteger(v) ? v.toLocaleString("en") : v.toPrecision(4));
const percent = (share) => `${(share * 100).toFixed(share < 0.1 ? 1 : 0)} %`;

/**
 * How each stat is shown: ``label``, ``text(value, context)`` and ``meaning``. ``context``:
 * ``{what}`` (what the blocks came from: "the texture", "the textures", "the image"),
 * ``width`` and ``height`` (the result's). Stats not named here are shown by their name.
 */
const FIGURES = {
  largest_copy: {
    label: "largest piece copied whole",
    text: (v, c) => `${percent(v)} of ${c.what}`,
    meaning: "The biggest region of the result that is one verbatim copy of the source, as " +
      "a share of its area: the lower, the less a repeat can be spotted.",
  },
  unused: {
    label: "never used",
    text: (v, c) => `${percent(v)} of ${c.what}`,
    meaning: "The share of the source's pixels that appear nowhere in the result: the lower, " +
      "the more of the source's variety the result shows.",
  },
  seam_error_mean: {
    label: "seam mismatch",
    text: (v) => `${number(v)} per seam pixel`,
    meaning: "The mean squared colour difference (channels 0 to 1) between the two blocks " +
      "that meet at each seam pixel: 0 is an invisible seam. Show the seams to see where.",
  },
  seam_error_total: {
    label: "seam mismatch, all seams",
    text: (v) => number(v),
    meaning: "The same difference summed over every seam pixel.",
  },
  correspondence_error: {
    label: "unlike the target",
    text: (v) => number(v),
    meaning: "The mean squared difference between the target and what the result shows of " +
      "it (its correspondence map): the lower, the more the result resembles the target.",
  },
  blocks: {
    label: "blocks placed",
    text: (v) => number(v),
    meaning: "How many blocks of the source were laid to fill what the mask marks.",
  },
  filled_pixels: {
    label: "pixels filled",
    text: (v, c) => `${number(v)} (${percent(v / (c.width * c.height))} of the image)`,
    meaning: "The pixels the mask marked, now taken from elsewhere in the source; every " +
      "other pixel is the image's own.",
  },
  light: {
    label: "light (x, y, z)",
    text: (v) => v.map((x) => x.toFixed(3)).join(", "),
    meaning: "The direction the light comes from, as estimated from the target's shading " +
      "(or as given): the layers are shaded by it.",
  },
  albedo: {
    label: "surface brightness",
    text: (v) => number(v),
    meaning: "ρ of the shading fitted to the target's lit pixels, I = ρ (n · S) + a: how " +
      "bright the surface is where it faces the light.",
  },
  ambient_fit: {
    label: "ambient light",
    text: (v) => number(v),
    meaning: "a of the same fit: the light every point of the surface gets, whatever it faces.",
  },
  clusters: {
    label: "surface patches",
    text: (v) => number(v),
    meaning: "The groups of similar normals and places (k-means) the surface was cut into " +
      "(see the clusters download).",
  },
  patches: {
    label: "connected patches",
    text: (v) => number(v),
    meaning: "The connected pieces of those groups: each is laid with its own texture " +
      "orientation, following its mean normal.",
  },
  layer_size: {
    label: "layer size",
    text: (v) => `${v[0]} × ${v[1]}`,
    meaning: "The size each layer was quilted to before it was laid on the surface.",
  },
  colors: {
    label: "edge colours",
    text: (v) => number(v),
    meaning: "The colours an edge can have: a tile exists for every combination, so that " +
      "tiles sharing an edge colour join seamlessly.",
  },
  tile: {
    label: "tile side",
    text: (v) => `${v} px`,
    meaning: "The side of each square tile.",
  },
  tiles: {
    label: "tiles",
    text: (v) => number(v),
    meaning: "How many tiles the atlas holds (one per combination of edge colours).",
  },
  atlas: {
    label: "atlas size",
    text: (v) => `${v[0]} × ${v[1]}`,
    meaning: "The size of the image that holds every tile; the manifest says where each is.",
  },
};

/** A stat's value as plain text (one the table above does not name), or null for one the
 * page does not show (a list of objects, an object). */
function plain(name, value) {
  if (typeof value === "number") return number(value);
  if (Array.isArray(value) && value.length && value.every((v) => typeof v === "number")) {
    if (name.endsWith("_size") && value.length === 2) return `${value[0]} × ${value[1]}`;
    return value.map((v) => (Number.isInteger(v) ? String(v) : v.toFixed(3))).join(", ");
  }
  return null;
}

/**
 * The figures of a finished job, in words: ``[label, text, meaning]`` for each stat of
 * ``stats`` (in its order; those the page cannot show are left out). ``context``: ``{what,
 * width, height}`` (see :data:`FIGURES`).
 */
export function explainStats(stats, context) {
  const shown = [];
  for (const [name, value] of Object.entries(stats || {})) {
    const figure = FIGURES[name];
    let text = null;
    try {
      text = figure ? figure.text(value, context) : plain(name, value);
    } catch {
      text = plain(name, value); // a value of another shape than expected: shown plainly
    }
    if (text === null) continue;
    shown.push([figure?.label || name.replaceAll("_", " "), text, figure?.meaning || ""]);
  }
  return shown;
}
