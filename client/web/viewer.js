// The result panel: the image at a zoom, a 3×3 tiling of it, the input beside it, the seams
// laid over it, the downloads and the job's figures.

const $ = (id) => document.getElementById(id);

/** Object URLs made for one result; revoked when the next result replaces it. */
const urls = [];

function objectUrl(blob) {
  const url = URL.createObjectURL(blob);
  urls.push(url);
  return url;
}

function loaded(img) {
  return img.complete && img.naturalWidth
    ? Promise.resolve()
    : new Promise((resolve, reject) => {
      img.addEventListener("load", () => resolve(), { once: true });
      img.addEventListener("error", () => reject(new Error("the image could not be shown")),
        { once: true });
    });
}

export class Viewer {
  constructor() {
    this.width = 0;
    this.height = 0;
    this.seamsUrl = null;
    this.loadSeams = null;
    this.zoom = $("zoom");
    this.seams = $("seams");
    this.zoom.addEventListener("input", () => this.layout());
    $("zoom-fit").addEventListener("click", () => this.fit());
    $("zoom-1").addEventListener("click", () => this.setZoom(100));
    for (const radio of document.querySelectorAll('input[name="view"]')) {
      radio.addEventListener("change", () => this.layout());
    }
    this.seams.addEventListener("change", () => this.toggleSeams());
    // Keyboard zoom on the picture itself: + and - (the range is keyboard-usable too).
    $("stage").addEventListener("keydown", (event) => {
      if (event.key === "+" || event.key === "=") this.setZoom(Number(this.zoom.value) * 2);
      else if (event.key === "-") this.setZoom(Number(this.zoom.value) / 2);
      else return;
      event.preventDefault();
    });
  }

  get view() {
    return document.querySelector('input[name="view"]:checked').value;
  }

  /** Forget the shown result (a new job starts). */
  clear() {
    for (const url of urls.splice(0)) URL.revokeObjectURL(url);
    this.width = this.height = 0;
    this.seamsUrl = null;
    this.loadSeams = null;
    this.seams.checked = false;
    this.seams.disabled = true;
    $("seams-info").textContent = "";
    $("seam-overlay").hidden = true;
    $("seam-overlay").removeAttribute("src");
    $("result-figure").hidden = true;
    $("input-figure").hidden = true;
    $("empty").hidden = false;
    $("downloads").hidden = true;
    $("companion-downloads").replaceChildren();
    $("stats").replaceChildren();
  }

  /**
   * Show a result.
   *
   * ``result``: the PNG blob, ``resultName`` its download name, ``downloadLabel`` its link's
   * text ("Download PNG"); ``input``: the file shown
   * beside it (the texture, a matting's target), ``inputLabel`` its caption ("Input"),
   * ``resultLabel`` the result's ("Result"); ``view``: the view to switch to, if any;
   * ``layout``: the layout JSON blob or null, ``layoutName`` its download name;
   * ``companions``: [[name, blob, label?, download name]] (the names are the service's);
   * ``loadSeams``: async () => seams PNG blob, or null where there are none (with ``noSeams``,
   * why); ``stats``: [[label, text]].
   */
  async show({
    result, resultName, downloadLabel, input, inputLabel, resultLabel, view, layout, layoutName,
    companions, loadSeams, noSeams, stats,
  }) {
    const resultUrl = objectUrl(result);
    const image = $("result-image");
    image.src = resultUrl;
    $("input-image").src = objectUrl(input);
    $("input-caption").textContent = inputLabel || "Input";
    $("input-image").alt = inputLabel ? `${inputLabel} image` : "Input texture";
    await loaded(image);
    this.width = image.naturalWidth;
    this.height = image.naturalHeight;
    $("tiled").style.backgroundImage = `url("${resultUrl}")`;
    $("result-caption").textContent = `${resultLabel || "Result"}, ${this.width} × ${this.height}`;
    $("result-image").alt = resultLabel || "Result";
    if (view) document.querySelector(`input[name="view"][value="${view}"]`).checked = true;
    this.loadSeams = loadSeams;
    this.seams.disabled = !loadSeams;
    $("seams-info").textContent = loadSeams ? "" : noSeams || "";

    const png = $("download-png");
    png.href = resultUrl;
    png.download = resultName;
    png.textContent = downloadLabel || "Download PNG";
    const layoutLink = $("download-layout");
    $("layout-item").hidden = !layout;
    if (layout) {
      layoutLink.href = objectUrl(layout);
      layoutLink.download = layoutName;
    }
    const list = $("companion-downloads");
    for (const [companion, blob, label, filename] of companions) {
      const link = document.createElement("a");
      link.className = "download-companion";
      link.href = objectUrl(blob);
      link.download = filename;
      link.dataset.companion = companion;
      link.textContent = `Download ${label || `companion ${companion}`}`;
      const item = document.createElement("li");
      item.append(link);
      list.append(item);
    }
    const dl = $("stats");
    for (const [label, text] of stats) {
      const term = document.createElement("dt");
      term.textContent = label;
      const value = document.createElement("dd");
      value.textContent = text;
      dl.append(term, value);
    }
    $("empty").hidden = true;
    $("result-figure").hidden = false;
    $("downloads").hidden = false;
    // A result wider than the stage starts fitted to it; a smaller one at 1:1.
    if (this.width * Number(this.zoom.value) / 100 > $("stage").clientWidth - 32) this.fit();
    this.layout();
    if (window.matchMedia("(max-width: 760px)").matches) {
      $("result").scrollIntoView({ block: "start" }); // stacked panels: the result is below
    }
  }

  setZoom(percent) {
    const { min, max, step } = this.zoom;
    const snapped = Math.round(percent / Number(step)) * Number(step);
    this.zoom.value = String(Math.min(Number(max), Math.max(Number(min), snapped)));
    this.layout();
  }

  /** The largest zoom at which the current view fits the stage's width. */
  fit() {
    if (!this.width) return;
    const across = { single: 1, tiled: 3, side: 2 }[this.view];
    const room = $("stage").clientWidth - 32;
    const step = Number(this.zoom.step);
    const percent = Math.floor((room / (this.width * across)) * 100 / step) * step;
    this.setZoom(Math.max(Number(this.zoom.min), percent));
  }

  async toggleSeams() {
    if (this.seams.checked && !this.seamsUrl && this.loadSeams) {
      this.seams.disabled = true;
      try {
        this.seamsUrl = objectUrl(await this.loadSeams());
        $("seam-overlay").src = this.seamsUrl;
      } catch (error) {
        this.seams.checked = false;
        $("seams-info").textContent = `The seams could not be loaded: ${error.message}`;
      } finally {
        this.seams.disabled = !this.loadSeams;
      }
    }
    this.layout();
  }

  /** Apply the view, zoom and seam toggle to the elements. */
  layout() {
    const zoom = Number(this.zoom.value) / 100;
    $("zoom-value").textContent = `${this.zoom.value} %`;
    if (!this.width) return;
    const view = this.view;
    const w = this.width * zoom;
    const h = this.height * zoom;
    const seams = this.seams.checked && this.seamsUrl;
    const stage = $("stage");
    stage.classList.toggle("pixelated", zoom >= 2);
    stage.classList.toggle("side", view === "side");

    $("input-figure").hidden = view !== "side";
    const input = $("input-image");
    if (input.naturalWidth) input.style.width = `${input.naturalWidth * zoom}px`;

    document.querySelector("#result-figure .layers").hidden = view === "tiled";
    for (const id of ["result-image", "seam-overlay"]) {
      $(id).style.width = `${w}px`;
      $(id).style.height = `${h}px`;
    }
    $("seam-overlay").hidden = !seams;

    const tiled = $("tiled");
    tiled.hidden = view !== "tiled";
    tiled.style.width = `${3 * w}px`;
    tiled.style.height = `${3 * h}px`;
    const layers = [`url("${$("result-image").src}")`];
    if (seams) layers.unshift(`url("${this.seamsUrl}")`);
    tiled.style.backgroundImage = layers.join(", ");
    tiled.style.backgroundSize = `${w}px ${h}px`;
  }
}
