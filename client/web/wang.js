// A Wang tile set's preview: a 6×6 aperiodic arrangement of its tiles, composed on a canvas
// from the atlas and its manifest as a game would lay them out (Cohen et al., "Wang Tiles for
// Image and Texture Generation", 2003, §3.1), with a re-roll and the seed that makes it.

const $ = (id) => document.getElementById(id);

/** Tiles across and down the preview. */
export const PREVIEW_TILES = 6;

/** The manifest's format name (quilting.wang, version 1). */
const FORMAT = "quilting.wang";

/** The largest canvas side the preview draws at full size; larger tiles are scaled down. */
const MAX_SIDE = 8192;

/** Seeds of the arrangement: 0 .. 2^32 - 1. */
const SEEDS = 2 ** 32;

/** A 32-bit seeded generator (mulberry32): a function giving numbers in [0, 1). */
export function prng(seed) {
  let a = seed >>> 0;
  return () => {
    a = (a + 0x6d2b79f5) >>> 0;
    let t = a;
    t = Math.imul(t ^ (t >>> 15), t | 1);
    t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
}

/**
 * An aperiodic ``rows`` × ``cols`` arrangement of a complete set of ``colors`` colours per
 * edge: tile indices, row by row. Cells are filled row by row; a cell's north colour is the
 * south colour of the tile above, its west colour the east colour of the tile on its left
 * (drawn at random on the first row and column), its east and south colours drawn at random;
 * ``tileOf(n, e, s, w)`` gives the index of the one tile with those edges.
 */
export function arrange(colors, rows, cols, seed, tileOf) {
  const random = prng(seed);
  const draw = () => Math.floor(random() * colors);
  const south = Array.from({ length: cols }, draw); // the colours above the first row
  const east = Array.from({ length: rows }, draw); // the colours left of the first column
  const tiles = [];
  for (let i = 0; i < rows; i += 1) {
    let west = east[i];
    const row = [];
    for (let j = 0; j < cols; j += 1) {
      const n = south[j];
      const e = draw();
      const s = draw();
      row.push(tileOf(n, e, s, west));
      south[j] = s;
      west = e;
    }
    tiles.push(row);
  }
  return tiles;
}

/** The manifest checked: its tile size, colours and tiles by their edges; throws if it is not
 * one (another format, a tile missing for some edges). */
function readManifest(manifest) {
  if (!manifest || manifest.format !== FORMAT) {
    throw new Error(`the manifest is not a ${FORMAT} document`);
  }
  const { tile, colors, tiles } = manifest;
  if (!Number.isInteger(tile) || tile < 1 || !Number.isInteger(colors) || colors < 1 ||
    !Array.isArray(tiles)) {
    throw new Error("the manifest has no tile size, colours or tiles");
  }
  const byEdges = new Map();
  for (const entry of tiles) byEdges.set([entry.n, entry.e, entry.s, entry.w].join(","), entry);
  const tileOf = (n, e, s, w) => {
    const entry = byEdges.get([n, e, s, w].join(","));
    if (!entry) throw new Error(`the set has no tile with edges n ${n}, e ${e}, s ${s}, w ${w}`);
    return entry.index;
  };
  const byIndex = new Map(tiles.map((entry) => [entry.index, entry]));
  return { tile, colors, tileOf, byIndex };
}

export class WangPreview {
  constructor() {
    this.canvas = $("wang-preview");
    this.seed = $("wang-seed");
    this.set = null; // the read manifest
    this.atlas = null; // the atlas as an ImageBitmap
    this.url = null; // object URLs of the downloads
    this.manifestUrl = null;
    this.drawing = 0; // a counter: only the latest drawing's PNG becomes the download
    $("wang-reroll").addEventListener("click", () => {
      this.draw(crypto.getRandomValues(new Uint32Array(1))[0]);
    });
    this.seed.addEventListener("change", () => {
      const seed = Number(this.seed.value);
      if (Number.isInteger(seed) && seed >= 0 && seed < SEEDS) this.draw(seed);
    });
    $("wang-actual").addEventListener("change", () => this.layout());
  }

  /** Forget the shown set (a new job starts). */
  clear() {
    this.drawing += 1; // a drawing's PNG still being made is not offered
    this.atlas?.close();
    this.atlas = null;
    this.set = null;
    for (const url of [this.url, this.manifestUrl]) if (url) URL.revokeObjectURL(url);
    this.url = this.manifestUrl = null;
    $("wang").hidden = true;
    $("manifest-item").hidden = true;
    $("preview-item").hidden = true;
    $("download-preview").removeAttribute("href");
    delete this.canvas.dataset.arrangement;
    delete this.canvas.dataset.seed;
  }

  /**
   * Show a set: ``atlas`` (the PNG blob), ``manifest`` (the parsed JSON), ``manifestBlob``
   * and ``manifestName`` (its download), the preview drawn for ``seed``. The manifest's
   * download is offered even when the preview cannot be drawn; then this throws why.
   */
  async show({ atlas, manifest, manifestBlob, manifestName, seed }) {
    this.manifestUrl = URL.createObjectURL(manifestBlob);
    const link = $("download-manifest");
    link.href = this.manifestUrl;
    link.download = manifestName;
    $("manifest-item").hidden = false;
    this.set = readManifest(manifest);
    // Pixels as the file has them: drawn 1:1, each tile is the atlas's, byte for byte.
    this.atlas = await createImageBitmap(atlas,
      { premultiplyAlpha: "none", colorSpaceConversion: "none" });
    $("wang").hidden = false;
    this.draw(seed);
  }

  /** Lay out and draw the arrangement of ``seed``. */
  draw(seed) {
    if (!this.set || !this.atlas) return;
    const { tile, colors, tileOf, byIndex } = this.set;
    const arrangement = arrange(colors, PREVIEW_TILES, PREVIEW_TILES, seed, tileOf);
    const full = PREVIEW_TILES * tile;
    const cell = Math.min(tile, Math.floor(MAX_SIDE / PREVIEW_TILES)); // whole pixels
    const side = cell * PREVIEW_TILES;
    const canvas = this.canvas;
    canvas.width = canvas.height = side;
    const context = canvas.getContext("2d");
    context.imageSmoothingEnabled = side < full; // 1:1 copies unless scaled down
    context.clearRect(0, 0, side, side);
    arrangement.forEach((row, i) => row.forEach((index, j) => {
      const { x, y } = byIndex.get(index);
      context.drawImage(this.atlas, x, y, tile, tile, j * cell, i * cell, cell, cell);
    }));
    canvas.dataset.arrangement = JSON.stringify(arrangement);
    canvas.dataset.seed = String(seed);
    canvas.setAttribute("aria-label", `${PREVIEW_TILES} × ${PREVIEW_TILES} tiles of the set ` +
      `laid out for seed ${seed}: every edge meets one of the same colour`);
    this.seed.value = String(seed);
    $("wang-info").textContent = side < full
      ? `Shown at ${side} × ${side} pixels (the tiles scaled down).`
      : `${side} × ${side} pixels: ${PREVIEW_TILES} × ${PREVIEW_TILES} tiles of ${tile} × ${tile}.`;
    this.layout();
    this.offer(seed);
  }

  /** Fitted to the panel, or at its own size (scrolled). */
  layout() {
    this.canvas.classList.toggle("actual", $("wang-actual").checked);
  }

  /** The drawing as the preview's download (its PNG made after each drawing). */
  offer(seed) {
    const link = $("download-preview");
    link.removeAttribute("href");
    $("preview-item").hidden = true;
    const drawing = ++this.drawing;
    this.canvas.toBlob((blob) => {
      if (!blob || drawing !== this.drawing) return;
      if (this.url) URL.revokeObjectURL(this.url);
      this.url = URL.createObjectURL(blob);
      link.href = this.url;
      link.download = `quilting-wang-preview-${seed}.png`;
      $("preview-item").hidden = false;
    }, "image/png");
  }
}
