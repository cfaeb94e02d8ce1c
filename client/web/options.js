// The options form, built from the service's own schemas (/openapi.json), so every option
// the service takes is here with its default, limits and explanation, and new ones appear
// without a change to the page.

/** The options schema of each operation, by its component name in /openapi.json. */
export const SCHEMAS = {
  synthesize: "SynthesizeOptions",
  transfer: "TransferOptions",
  tile: "TileOptions",
  matte: "MatteOptions",
  fill: "FillOptions",
  extend: "ExtendOptions",
  wang: "WangOptions",
};

/** Shown outside "More options": what most runs change. */
const MAIN = new Set([
  "width", "height", "block", "overlap", "mode", "seed", "tileable",
  "alpha", "iterations", "correspondence", "axes", "band",
  "clusters", "light", "scale", "ambient", "method", "top", "bottom", "left", "right",
  "transforms", "colors", "tile",
]);

/** Text options whose common values are offered as a menu, with "other" for any other text
 * (the schema says "a string": these are the values its description names first). */
const PRESET_TEXT = {
  transforms: {
    values: ["none", "flips", "rotations", "all"],
    other: "names…",
    placeholder: "identity, rot90, flip_x, …",
    example: "rot90, flip_x",
  },
};

/** The menu entry that shows the free-text box of a PRESET_TEXT field. */
const OTHER = "(other)";

/** Block presets: a fraction of the texture's (a matting's first layer's) shorter side (the paper's blocks are small
 * against the texture: more candidates, more variety; larger keeps larger structures). */
export const PRESETS = [
  { name: "Fine", fraction: 1 / 8, label: "⅛" },
  { name: "Medium", fraction: 1 / 5, label: "⅕" },
  { name: "Coarse", fraction: 1 / 3, label: "⅓" },
];

/** Defaults the page sets where the schema has none (a synthesis needs a size). */
const PAGE_DEFAULTS = { width: 512, height: 512 };

/** A property's schema without its "anyOf [x, null]" wrapper, and whether null is allowed. */
function unwrap(prop) {
  const variants = prop.anyOf || [];
  const concrete = variants.find((v) => v.type !== "null");
  const nullable = variants.some((v) => v.type === "null");
  return { spec: concrete ? { ...prop, ...concrete } : prop, nullable };
}

/** The length of a fixed-length list of numbers (a direction such as [x, y, z]), else 0. */
function vectorLength(spec) {
  const item = spec.items || {};
  const numeric = item.type === "number" || item.type === "integer";
  const fixed = spec.minItems !== undefined && spec.minItems === spec.maxItems;
  return spec.type === "array" && numeric && fixed && spec.minItems > 0 ? spec.minItems : 0;
}

function kindOf(spec, name) {
  if (spec.enum) return "choice";
  if (spec.type === "string" && name in PRESET_TEXT) return "preset";
  if (spec.type === "boolean") return "boolean";
  if (spec.type === "integer" || spec.type === "number") return spec.type;
  if (vectorLength(spec)) return "vector";
  if (spec.type === "array") return "json";
  return "text";
}

/** How a vector of ``length`` numbers is typed: "x, y, z" for three. */
function vectorExample(length) {
  const names = { 2: "x, y", 3: "x, y, z", 4: "x, y, z, w" }[length];
  return names || `${length} numbers separated by commas`;
}

/** "1, 1, 2" (or "1 1 2", "[1, 1, 2]") as [1, 1, 2]; throws an Error naming the field. */
function parseVector(name, raw, length, integer, nullable) {
  const inner = raw.replace(/^\[(.*)\]$/s, "$1").trim();
  const parts = inner.split(/\s*,\s*|\s+/).filter((part) => part !== "");
  const numbers = parts.map(Number);
  const bad = parts.find((part, i) => !Number.isFinite(numbers[i]) ||
    (integer && !Number.isInteger(numbers[i])));
  if (parts.length !== length || bad !== undefined) {
    const what = bad !== undefined ? `"${bad}" is not ${integer ? "an integer" : "a number"}`
      : `${parts.length} number${parts.length === 1 ? "" : "s"} given`;
    const empty = nullable ? ", or leave it empty for auto" : "";
    throw new Error(`${name}: give ${length} numbers as "${vectorExample(length)}"${empty} ` +
      `(${what})`);
  }
  return numbers;
}

/** The text a default is shown as, and what an untouched field holds. */
function shownDefault(value, kind) {
  if (value === null || value === undefined) return "";
  if (kind === "vector" && Array.isArray(value)) return value.join(", ");
  if (typeof value === "object") return JSON.stringify(value);
  return String(value);
}

/**
 * One form field for a schema property.
 *
 * Returns ``{element, read}``: ``read()`` gives ``{set, value}`` (set false: left at the
 * default, not sent) or throws an Error naming the field.
 */
function field(name, prop, required) {
  const { spec, nullable } = unwrap(prop);
  const kind = kindOf(spec, name);
  const id = `opt-${name}`;
  const fallback = name in PAGE_DEFAULTS ? PAGE_DEFAULTS[name] : spec.default;
  const wrapper = document.createElement("div");
  wrapper.className = `field field-${kind}`;
  const label = document.createElement("label");
  label.htmlFor = id;
  label.textContent = name;
  const badge = document.createElement("span");
  badge.className = "default";
  // A null default is "decided for you" (overlap, band, alpha), or "off" for a choice.
  const unset = kind === "choice" ? "none" : "auto";
  const defaultText = nullable && fallback === null ? unset : shownDefault(fallback, kind);
  badge.textContent = required ? "required" : `default ${defaultText || "none"}`;
  label.append(" ", badge);

  let input;
  let other = null; // the free-text box of a "preset" field
  if (kind === "preset") {
    const preset = PRESET_TEXT[name];
    input = document.createElement("select");
    for (const value of preset.values) input.add(new Option(value, value));
    input.add(new Option(preset.other, OTHER));
    other = document.createElement("input");
    other.type = "text";
    other.spellcheck = false;
    other.id = `${id}-other`;
    other.name = `${name}-other`;
    other.className = "other";
    other.placeholder = preset.placeholder;
    other.setAttribute("aria-label", `${name}: ${preset.other.replace(/…$/, "")}`);
    const start = shownDefault(fallback);
    if (preset.values.includes(start)) {
      input.value = start;
    } else {
      input.value = OTHER;
      other.value = start;
    }
    other.hidden = input.value !== OTHER;
    input.addEventListener("change", () => {
      other.hidden = input.value !== OTHER;
      if (!other.hidden) other.focus();
    });
  } else if (kind === "choice") {
    input = document.createElement("select");
    if (nullable) input.add(new Option("(none)", ""));
    for (const value of spec.enum) input.add(new Option(value, value));
    input.value = shownDefault(fallback);
  } else if (kind === "boolean") {
    input = document.createElement("input");
    input.type = "checkbox";
    input.checked = Boolean(fallback);
  } else {
    input = document.createElement("input");
    if (kind === "integer" || kind === "number") {
      input.type = "number";
      input.inputMode = kind === "integer" ? "numeric" : "decimal";
      // A multiple the schema asks for (a Wang tile's even side) is the field's step.
      if (spec.multipleOf !== undefined) input.step = String(spec.multipleOf);
      else input.step = kind === "integer" ? "1" : "any";
      if (spec.minimum !== undefined) input.min = String(spec.minimum);
      if (spec.maximum !== undefined && spec.maximum < 2 ** 53) input.max = String(spec.maximum);
    } else {
      input.type = "text";
      input.spellcheck = false;
    }
    input.value = shownDefault(fallback, kind);
    if (nullable) input.placeholder = "auto";
    if (kind === "vector") {
      const example = vectorExample(vectorLength(spec));
      input.placeholder = nullable ? `auto, or ${example}` : example;
    }
  }
  input.id = id;
  input.name = name;
  const hint = document.createElement("p");
  hint.className = "hint";
  hint.id = `${id}-hint`;
  // Shown as one line (style.css); read out whole as the field's description, and shown
  // whole on demand ("more").
  hint.textContent = spec.description || "";
  hint.title = spec.description || "";
  input.setAttribute("aria-describedby", hint.id);
  wrapper.append(label, input);
  if (other) {
    other.setAttribute("aria-describedby", hint.id);
    wrapper.append(other);
  }
  if (name === "seed") wrapper.append(diceButton(input));
  wrapper.append(hint);
  if (spec.description) wrapper.append(helpToggle(hint, name));

  /** The text a "preset" field stands for: its menu's value, or the names typed as "other"
   * (comma-separated, spaces dropped). */
  const presetText = () => (input.value !== OTHER ? input.value
    : other.value.split(",").map((part) => part.trim()).filter(Boolean).join(","));
  const initial = kind === "boolean" ? String(input.checked)
    : kind === "preset" ? presetText() : input.value;
  /** The field's value (see ``read``), marking the input invalid while it throws. */
  function read() {
    const shown = other && !other.hidden ? other : input;
    try {
      const value = parse();
      shown.removeAttribute("aria-invalid");
      return value;
    } catch (error) {
      shown.setAttribute("aria-invalid", "true");
      error.input = shown;
      throw error;
    }
  }
  function parse() {
    if (kind === "boolean") {
      return { set: required || String(input.checked) !== initial, value: input.checked };
    }
    if (kind === "preset") {
      const text = presetText();
      if (text === "") {
        throw new Error(`${name}: give the names separated by commas (example: ` +
          `${PRESET_TEXT[name].example}), or pick one from the menu`);
      }
      return { set: required || text !== initial, value: text };
    }
    const raw = input.value.trim();
    if (!required && raw === initial) return { set: false, value: undefined };
    if (raw === "") {
      if (nullable) return { set: true, value: null };
      if (required || fallback === undefined) throw new Error(`${name}: a value is required`);
      return { set: false, value: undefined };
    }
    if (kind === "integer" || kind === "number") {
      const number = Number(raw);
      if (!Number.isFinite(number) || (kind === "integer" && !Number.isInteger(number))) {
        throw new Error(`${name}: ${raw} is not ${kind === "integer" ? "an integer" : "a number"}`);
      }
      return { set: true, value: number };
    }
    if (kind === "vector") {
      const length = vectorLength(spec);
      const integer = spec.items.type === "integer";
      return { set: true, value: parseVector(name, raw, length, integer, nullable) };
    }
    if (kind === "json") {
      try {
        return { set: true, value: JSON.parse(raw) };
      } catch {
        throw new Error(`${name}: not valid JSON (example: [[[0, 0, 0], [20, 20, 20]]])`);
      }
    }
    return { set: true, value: raw };
  }
  /** Show ``value`` (as ``read`` gives it) in the field; undefined: its default. */
  function write(value) {
    const shown = value === undefined ? fallback : value;
    if (kind === "boolean") {
      input.checked = Boolean(shown);
    } else if (kind === "preset") {
      const text = shownDefault(shown);
      const listed = PRESET_TEXT[name].values.includes(text);
      input.value = listed ? text : OTHER;
      other.value = listed ? "" : text.split(",").join(", ");
      other.hidden = listed;
    } else {
      input.value = shownDefault(shown, kind);
    }
    for (const shownInput of [input, other]) shownInput?.removeAttribute("aria-invalid");
  }
  return { element: wrapper, input, read, write };
}

/**
 * The form of one operation's options.
 *
 * ``schemas`` is ``components.schemas`` of /openapi.json. Fields go into ``main`` (common)
 * and ``extra`` (the rest). Returns ``{values(), input(name), set(values)}``: ``values()``
 * is the options object to send (only what differs from the service's defaults, plus
 * required fields); ``set(values)`` puts such an object back into the fields.
 *
 * ``outside`` names options the page asks for elsewhere (the weights, beside each texture):
 * ``{name: read}``, ``read()`` giving ``{set, value}`` as a field's does; they get no field
 * here, and are sent only when the schema has them.
 */
export function buildOptions(schemas, operation, main, extra, outside = {}) {
  const schema = schemas[SCHEMAS[operation]];
  main.replaceChildren();
  extra.replaceChildren();
  const fields = new Map();
  if (!schema) return { values: () => ({}), input: () => null, set: () => {} };
  const required = new Set(schema.required || []);
  for (const [name, prop] of Object.entries(schema.properties || {})) {
    if (name in outside) {
      fields.set(name, { read: outside[name], input: null });
      continue;
    }
    const made = field(name, prop, required.has(name));
    fields.set(name, made);
    (MAIN.has(name) || required.has(name) ? main : extra).append(made.element);
  }
  return {
    values() {
      const values = {};
      for (const [name, made] of fields) {
        const { set, value } = made.read();
        if (set) values[name] = value;
      }
      return values;
    },
    input(name) {
      return fields.get(name)?.input ?? null;
    },
    /** Set every field to ``values`` (an options object as ``values()`` gives it): a field
     * it does not name goes back to its default; the options asked for outside are left. */
    set(values) {
      for (const [name, made] of fields) made.write?.(values[name]);
    },
  };
}

/** The block side of a preset for a texture of ``width`` x ``height``: at least 3. */
export function presetBlock(fraction, width, height) {
  return Math.max(3, Math.round(Math.min(width, height) * fraction));
}

/**
 * The "more" button under a field's one-line help: it shows the whole text in place (and
 * "less" folds it again). A button, so that the keyboard reaches it and a screen reader says
 * whether the help is open.
 */
function helpToggle(hint, name) {
  const toggle = document.createElement("button");
  toggle.type = "button";
  toggle.className = "hint-more";
  toggle.textContent = "more";
  toggle.setAttribute("aria-expanded", "false");
  toggle.setAttribute("aria-controls", hint.id);
  // The name starts with the visible word (WCAG 2.5.3): "more help on block".
  toggle.setAttribute("aria-label", `more help on ${name}`);
  toggle.addEventListener("click", () => {
    const open = hint.classList.toggle("open");
    toggle.setAttribute("aria-expanded", String(open));
    toggle.textContent = open ? "less" : "more";
    toggle.setAttribute("aria-label", `${toggle.textContent} help on ${name}`);
  });
  return toggle;
}

/** Seeds the dice draws: any below 2^31, which every backend and JSON reader holds exactly. */
const DICE_SEEDS = 2 ** 31;

/**
 * "Another seed": a new random seed in the seed's field (the same options with another seed
 * give another texture; the seed in the field gives the same bytes again).
 */
function diceButton(input) {
  const dice = document.createElement("button");
  dice.type = "button";
  dice.className = "dice";
  dice.textContent = "Another seed";
  dice.setAttribute("aria-controls", input.id);
  dice.addEventListener("click", () => {
    const draw = new Uint32Array(1);
    crypto.getRandomValues(draw);
    input.value = String(draw[0] % DICE_SEEDS);
    input.dispatchEvent(new Event("input", { bubbles: true }));
    input.dispatchEvent(new Event("change", { bubbles: true }));
  });
  return dice;
}
