// Small DOM and formatting helpers shared by the views.

/** Create an element: h("td", {class: "num"}, "1.0", child, ...). Attributes starting with "on" are listeners. */
export function h(tag, attrs = {}, ...children) {
  const el = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v === undefined || v === null || v === false) continue;
    if (k.startsWith("on") && typeof v === "function") el.addEventListener(k.slice(2), v);
    else if (k === "dataset") Object.assign(el.dataset, v);
    else el.setAttribute(k, v === true ? "" : String(v));
  }
  append(el, children);
  return el;
}

function append(el, children) {
  for (const c of children) {
    if (c === undefined || c === null || c === false) continue;
    if (Array.isArray(c)) append(el, c);
    else el.append(c instanceof Node ? c : document.createTextNode(String(c)));
  }
}

/** An SVG element with attributes. */
export function s(tag, attrs = {}, ...children) {
  const el = document.createElementNS("http://www.w3.org/2000/svg", tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v === undefined || v === null) continue;
    el.setAttribute(k, String(v));
  }
  for (const c of children.flat()) {
    if (c === undefined || c === null || c === false) continue;
    el.append(c instanceof Node ? c : document.createTextNode(String(c)));
  }
  return el;
}

export const $ = (sel, root = document) => root.querySelector(sel);
export const $$ = (sel, root = document) => [...root.querySelectorAll(sel)];

/** The value of the checked radio button `name` in `root`. */
export function radioValue(root, name) {
  return root.querySelector(`input[name="${name}"]:checked`).value;
}

/** Check the radio button `name` with `value` in `root`. */
export function checkRadio(root, name, value) {
  root.querySelector(`input[name="${name}"][value="${value}"]`).checked = true;
}

/** The run vocabulary (contract/vocabulary.py), from GET /api/v1/meta before any page draws (loadVocabulary). */
export const VOCABULARY = { terminal: new Set(), notCounted: new Set(), jobOutcomes: [], modes: [] };
/** The statuses a run ends in. */
export const TERMINAL = VOCABULARY.terminal;

/** Fill VOCABULARY from the server (its one definition; the dashboard keeps no copy). */
export async function loadVocabulary() {
  const res = await fetch("/api/v1/meta");
  if (!res.ok) throw new Error(`GET /api/v1/meta: ${res.status}`);
  const v = (await res.json()).vocabulary;
  for (const [set, values] of [[VOCABULARY.terminal, v.terminal], [VOCABULARY.notCounted, v.not_counted]]) {
    set.clear();
    values.forEach((s) => set.add(s));
  }
  VOCABULARY.jobOutcomes = v.job_outcomes;
  VOCABULARY.modes = v.modes;
}

export function badge(state) {
  return h("span", { class: `badge ${state || ""}` }, state || "–");
}

/** A number with a fixed count of significant decimals; "–" for null/undefined/NaN. */
export function num(v, digits = 3) {
  if (v === null || v === undefined || (typeof v === "number" && !Number.isFinite(v))) return "–";
  if (typeof v === "boolean") return v ? "yes" : "no";
  if (typeof v !== "number") return String(v);
  const a = Math.abs(v);
  if (a < 1e-12) return (0).toFixed(digits);
  if (a < 10 ** -digits || a >= 1e5) return v.toExponential(2);
  return v.toFixed(digits);
}

export function deg(rad) {
  return Number.isFinite(rad) ? `${((rad * 180) / Math.PI).toFixed(0)}°` : "";
}

export function duration(seconds) {
  if (seconds === null || seconds === undefined || !Number.isFinite(seconds)) return "–";
  if (seconds < 1) return "now";
  if (seconds < 90) return `~${Math.round(seconds)} s`;
  if (seconds < 5400) return `~${Math.round(seconds / 60)} min`;
  return `~${(seconds / 3600).toFixed(1)} h`;
}

export function when(iso) {
  if (!iso) return "–";
  const d = new Date(iso);
  return Number.isNaN(d.getTime()) ? iso : d.toLocaleString();
}

export function pose(p) {
  if (!p) return "–";
  const [x, y, a] = p;
  return `(${num(x, 2)}, ${num(y, 2)}${a === undefined || a === null ? "" : `, ${deg(a)}`})`;
}

let toastTimer = 0;
let toastKey = null;
/** A short message in the corner (role=status), red for problems, gone after 3 s (6 s); `key` names it for
 * `retoast`.  A gone toast leaves no text behind (a stale "queued" is neither seen nor read out). */
export function toast(message, bad = false, key = null) {
  const el = document.getElementById("toast");
  if (!el) return;
  el.textContent = message;
  el.classList.toggle("bad", bad);
  el.classList.add("show");
  toastKey = key;
  clearTimeout(toastTimer);
  toastTimer = setTimeout(() => {
    el.classList.remove("show");
    toastKey = null;
    toastTimer = setTimeout(() => { el.textContent = ""; }, 250); // after the fade
  }, bad ? 6000 : 3000);
}

/** Change the message of the toast shown under `key`, if it still is (3 s more); false when it has gone. */
export function retoast(key, message) {
  const el = document.getElementById("toast");
  if (!el || key === null || toastKey !== key || !el.classList.contains("show")) return false;
  toast(message, false, key);
  return true;
}

/** Call fn at most once per `ms`, trailing. */
export function debounce(fn, ms) {
  let timer = 0;
  return (...args) => {
    clearTimeout(timer);
    timer = setTimeout(() => fn(...args), ms);
  };
}

/** Report an unexpected failure without throwing into the console as uncaught. */
export function report(err, what = "") {
  if (err && err.name === "AbortError") return;
  const msg = err && err.detail ? err.detail : err && err.message ? err.message : String(err);
  toast(what ? `${what}: ${msg}` : msg, true);
  console.warn(what, err); // a warning, not an error: the dashboard kept working
}
