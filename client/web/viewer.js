// The result panel: the image at a zoom, a 3×3 tiling of it, the input beside it, the seams
// laid over it, the downloads and the job's figures.

const $ = (id) => document.getElementById(id);

/** How many times the result's width each view is: once, 3 tiled across, 2 side by side. */
const ACROSS = { single: 1, tiled: 3, side: 2 };

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
    $("download-seams").addEventListener("click", () => this.downloadSeams());
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
    this.seamsName = null;
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
    $("seams-item").hidden = true;
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
   * ``companions``: [[name, blob, label?, download name]] (the names are the service's),
   * each shown as a thumbnail in its link;
   * ``loadSeams``: async () => the seams PNG as ``{blob, name}``, or null where there are none
   * (with ``noSeams``, why); ``stats``: [[label, text, meaning?]], the meaning (a sentence)
   * shown under the value.
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
    $("seams-item").hidden = !loadSeams;

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
      const thumb = document.createElement("img");
      thumb.className = "thumb";
      thumb.src = link.href;
      thumb.alt = ""; // the link's text says what it is
      link.append(thumb, `Download ${label || `companion ${companion}`}`);
      const item = document.createElement("li");
      item.append(link);
      list.append(item);
    }
    const dl = $("stats");
    for (const [label, text, meaning] of stats) {
      const term = document.createElement("dt");
      term.textContent = label;
      const value = document.createElement("dd");
      value.textContent = text;
      if (meaning) {
        const why = document.createElement("span");
        why.className = "meaning";
        why.textContent = meaning;
        value.append(why);
      }
      dl.append(term, value);
    }
    $("empty").hidden = true;
    $("result-figure").hidden = false;
    $("downloads").hidden = false;
    // A view wider than the stage (the result, 3 across tiled, 2 side by side) starts fitted
    // to it; a smaller one at 1:1.
    const across = ACROSS[this.view];
    if (this.width * across * Number(this.zoom.value) / 100 > $("stage").clientWidth - 32) {
      this.fit();
    }
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
    const across = ACROSS[this.view];
    const room = $("stage").clientWidth - 32;
    const step = Number(this.zoom.step);
    const percent = Math.floor((room / (this.width * across)) * 100 / step) * step;
    this.setZoom(Math.max(Number(this.zoom.min), percent));
  }

  /** The seam overlay's object URL, fetched once per result; throws why it could not be. */
  async seamsLoaded() {
    if (!this.seamsUrl) {
      const loaded = this.loadSeams;
      const seams = await loaded();
      if (loaded !== this.loadSeams) throw new Error("another result is shown");
      this.seamsUrl = objectUrl(seams.blob);
      this.seamsName = seams.name;
      $("seam-overlay").src = this.seamsUrl;
    }
    return this.seamsUrl;
  }

  async toggleSeams() {
    if (this.seams.checked && !this.seamsUrl && this.loadSeams) {
      this.seams.disabled = true;
      try {
        await this.seamsLoaded();
      } catch (error) {
        this.seams.checked = false;
        $("seams-info").textContent = `The seams could not be loaded: ${error.message}`;
      } finally {
        this.seams.disabled = !this.loadSeams;
      }
    }
    this.layout();
  }

  /** "Download seam overlay PNG": saved under the service's name (``<result>-seams.png``). */
  async downloadSeams() {
    if (!this.loadSeams) return;
    const button = $("download-seams");
    button.disabled = true;
    try {
      const link = document.createElement("a");
      link.href = await this.seamsLoaded();
      link.download = this.seamsName;
      link.hidden = true;
      document.body.append(link);
      link.click();
      link.remove();
    } catch (error) {
      $("seams-info").textContent = `The seams could not be loaded: ${error.message}`;
    } finally {
      button.disabled = false;
    }
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
