// The HTTP API as the page uses it: requests with the API key, problem+json errors, and a
// job's server-sent events read through fetch (EventSource cannot send an API key).

/** A failed request: the service's problem document, or what went wrong on the way. */
export class ApiError extends Error {
  constructor(status, code, detail, field = null) {
    super(detail);
    this.status = status;
    this.code = code;
    this.detail = detail;
    this.field = field;
  }

  /** One line for a person: the detail first, then the code and status. */
  describe() {
    const where = this.status ? `HTTP ${this.status}` : "no answer";
    return `${this.detail} (${this.code}, ${where})`;
  }
}

function headers(key) {
  return key ? { Authorization: `Bearer ${key}` } : {};
}

/** The error of a non-2xx response: its problem+json when it has one. */
async function problemOf(response) {
  const text = await response.text();
  try {
    const problem = JSON.parse(text);
    if (problem && typeof problem.detail === "string") {
      return new ApiError(response.status, problem.code || "http_error", problem.detail,
        problem.field || null);
    }
  } catch {
    // Not JSON: a proxy's page or an empty body; the status line is all there is.
  }
  const detail = text.trim().slice(0, 200) || response.statusText || "request failed";
  return new ApiError(response.status, "http_error", detail);
}

/**
 * fetch with the API key; resolves to the Response when it is 2xx, throws ApiError otherwise.
 * A network failure (service down, connection cut) is an ApiError with status 0.
 */
export async function request(path, { method = "GET", body, key, signal } = {}) {
  let response;
  try {
    response = await fetch(path, { method, body, headers: headers(key), signal });
  } catch (error) {
    if (error.name === "AbortError") throw error;
    throw new ApiError(0, "network_error", `the service could not be reached: ${error.message}`);
  }
  if (!response.ok) throw await problemOf(response);
  return response;
}

/** GET a JSON document. */
export async function getJson(path, options) {
  return (await request(path, options)).json();
}

/** GET a body as a Blob (images, the layout). */
export async function getBlob(path, options) {
  return (await request(path, options)).blob();
}

/**
 * The file name a response's Content-Disposition gives it (its UTF-8 ``filename*`` first,
 * else the ASCII ``filename``), or ``fallback`` when it names none.
 */
export function downloadName(response, fallback) {
  const header = response.headers.get("Content-Disposition") || "";
  const extended = /filename\*\s*=\s*UTF-8''([^;\s]+)/i.exec(header);
  if (extended) {
    try {
      return decodeURIComponent(extended[1]);
    } catch {
      // A malformed escape: the plain name below is the next best.
    }
  }
  const plain = /filename\s*=\s*"([^"]*)"/i.exec(header);
  return plain && plain[1] ? plain[1] : fallback;
}

/**
 * GET a file the service names (a result, a companion, the layout): ``{blob, name}``, the
 * name from its Content-Disposition, ``fallback`` when it has none.
 */
export async function getFile(path, fallback, options) {
  const response = await request(path, options);
  return { blob: await response.blob(), name: downloadName(response, fallback) };
}

/**
 * Follow a job's event stream until its final event; ``onEvent(name, data)`` is called for
 * each event. Resolves to the final event's ``{name, data}``, or null if the stream ended
 * without one (the caller then polls).
 */
export async function followEvents(path, { key, signal, onEvent }) {
  const response = await request(path, { key, signal });
  const reader = response.body.pipeThrough(new TextDecoderStream()).getReader();
  let buffer = "";
  for (;;) {
    const { value, done } = await reader.read();
    if (done) return null;
    buffer += value.replace(/\r\n/g, "\n");
    let end;
    while ((end = buffer.indexOf("\n\n")) >= 0) {
      const block = buffer.slice(0, end);
      buffer = buffer.slice(end + 2);
      const event = parseEvent(block);
      if (!event) continue;
      onEvent(event.name, event.data);
      if (event.name !== "progress") {
        reader.cancel().catch(() => {});
        return event;
      }
    }
  }
}

/** One SSE block ("event: x\ndata: {...}") as {name, data}, or null for a comment. */
function parseEvent(block) {
  let name = "message";
  const data = [];
  for (const line of block.split("\n")) {
    if (line.startsWith(":")) continue;
    const colon = line.indexOf(":");
    const field = colon < 0 ? line : line.slice(0, colon);
    const value = colon < 0 ? "" : line.slice(colon + 1).replace(/^ /, "");
    if (field === "event") name = value;
    else if (field === "data") data.push(value);
  }
  if (!data.length) return null;
  try {
    return { name, data: JSON.parse(data.join("\n")) };
  } catch {
    return null;
  }
}

/** A job's state in words from a status event or document ("queued", "running: quilting"),
 * or null for a final one (its caller says how it ended). */
export function statusWords(data) {
  if (data.status === "queued") return "queued";
  if (data.status === "running") return `running: ${data.stage || "working"}`;
  return null;
}
