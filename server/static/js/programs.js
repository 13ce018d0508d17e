// The programs page: upload a planner program (file, name, kind, interpreter, arguments) and
// the list of your programs.  When the server runs without --enable-uploads the page says so
// instead of showing the form.  How programs run: docs/uploads.md.

import { $, $$, checkRadio, h, num, radioValue, report, toast, when } from "./dom.js";

/** Where a server message about an upload belongs: a form field's key, or null for the top. */
function fieldOfUploadMessage(msg) {
  const m = msg.toLowerCase();
  if (/content_base64|larger than|empty/.test(m)) return "file";
  if (/interpreter/.test(m)) return "interpreter";
  if (/python3/.test(m)) return "kind";
  if (/^name\b/.test(m)) return "name";
  return null;
}

const LOC_FIELD = { content_base64: "file", name: "name", kind: "kind", interpreter: "interpreter", args: "args" };
const INPUTS = { file: "#p-file", name: "#p-name", kind: 'input[name="p-kind"]', interpreter: "#p-interpreter", args: "#p-args" };

/** "astar.py (#7, Python)": how the dashboard names a program. */
export function programLabel(p) {
  return `${p.name} (#${p.id}, ${p.kind === "python" ? "Python" : p.interpreter || "executable"})`;
}

/** A file's name made acceptable as a program name (letters, digits, _ . + -). */
function cleanName(name) {
  return name.replace(/[^A-Za-z0-9_.+-]+/g, "_").slice(0, 100) || "program";
}

async function fileBase64(file) {
  const bytes = new Uint8Array(await file.arrayBuffer());
  let bin = "";
  for (let i = 0; i < bytes.length; i += 0x8000) bin += String.fromCharCode(...bytes.subarray(i, i + 0x8000));
  return btoa(bin);
}

function kib(bytes) {
  if (bytes >= 1 << 20) return `${num(bytes / (1 << 20), bytes % (1 << 20) ? 1 : 0)} MiB`;
  return bytes >= 1024 ? `${num(bytes / 1024, bytes % 1024 ? 1 : 0)} KiB` : `${bytes} bytes`;
}

export class ProgramsPage {
  constructor(store) {
    this.store = store;
    this.form = $("#upload-form");
    this.sandbox = null;
    this.autoName = "";
    this.form.addEventListener("submit", (ev) => {
      ev.preventDefault();
      this.upload().catch((err) => report(err, "Upload"));
    });
    $("#p-file").addEventListener("change", () => this.onFile());
    for (const r of $$('input[name="p-kind"]', this.form)) r.addEventListener("change", () => this.onKind());
  }

  get kind() {
    return radioValue(this.form, "p-kind");
  }

  set kind(v) {
    checkRadio(this.form, "p-kind", v);
    this.onKind();
  }

  async show() {
    await Promise.all([this.loadSandbox(), this.loadList()]);
  }

  /** Whether uploads are on; the form, or the plain statement that they are off. */
  async loadSandbox() {
    try {
      this.sandbox = await this.store.api.get("/api/v1/programs/sandbox");
    } catch (err) {
      $("#uploads-loading").textContent = `Cannot ask the server about uploads: ${err.detail || err.message}`;
      return;
    }
    const sb = this.sandbox;
    const on = Boolean(sb.uploads_enabled);
    $("#uploads-loading").hidden = true;
    $("#uploads-disabled").hidden = on;
    this.form.hidden = !on;
    $("#sandbox-panel").hidden = !on;
    if (!on) return;
    const sel = $("#p-interpreter");
    const keep = sel.value;
    sel.replaceChildren(h("option", { value: "" }, "none: run the file itself (a binary or a #! script)"),
      ...sb.interpreters.map((i) => h("option", { value: i }, i)));
    if (sb.interpreters.includes(keep)) sel.value = keep;
    const L = sb.limits || {};
    $("#p-file-desc").textContent = `At most ${kib(L.max_program_bytes)}.`;
    const iso = sb.isolation || {};
    const facts = [
      ["Runs as", iso.runs_as || "–"],
      ["Sandbox", iso.sandbox || "none"],
      ["Network", iso.network || "–"],
      ["Namespaces", (iso.namespaces || []).join(" + ") || "none"],
      ["System-call filter", iso.seccomp ? "seccomp allowlist" : "none"],
      ["Wall / CPU time", `${num(L.wall_s, 0)} s / ${num(L.cpu_s, 0)} s`],
      ["Memory", `${L.memory_mb} MiB ${iso.memory_limit === "per-process" ? "a process" : "for all its processes together"}`],
      ["Processes", L.processes],
      ["Output kept", `${L.output_kib} KiB each of stdout and stderr`],
    ];
    if (iso.note) facts.push(["Note", iso.note]);
    $("#sandbox-facts").replaceChildren(...facts.map(([k, v]) => h("div", {}, h("dt", {}, k), h("dd", {}, v))));
  }

  async loadList(highlight = null) {
    let page;
    try {
      page = await this.store.api.get("/api/v1/programs?limit=200");
    } catch (err) {
      report(err, "Programs");
      return;
    }
    this.store.notePrograms(page.data);
    const admin = this.store.user?.is_admin;
    // the actions next to the name, so they stay in view when the table scrolls sideways
    const cols = ["ID", "Name", "Actions", "Kind", "Arguments", "Size", "Uploaded", ...(admin ? ["Owner"] : [])];
    const head = h("thead", {}, h("tr", {}, cols.map((t) => h("th", { scope: "col", class: t === "Size" ? "num" : null }, t))));
    const rows = page.data.map((p) => h("tr", { dataset: { program: p.id }, class: p.id === highlight ? "new" : null },
      h("td", {}, p.id),
      h("td", {}, p.name, h("div", { class: "muted small" }, "SHA-256 ", h("code", { title: p.sha256 }, p.sha256.slice(0, 12)))),
      h("td", {}, h("span", { class: "downloads" },
        h("a", { href: `#/submit?program=${p.id}`, "aria-label": `Use program ${p.name} (#${p.id}) in a job` }, "Use in a job"),
        h("button", { type: "button", class: "small", "aria-label": `Download program ${p.name} (#${p.id})`,
          onclick: () => this.store.api.download(`/api/v1/programs/${p.id}/content`, p.name)
            .catch((err) => report(err, "Download")) }, "Download"))),
      h("td", {}, p.kind === "python" ? "Python" : `executable${p.interpreter ? ` (${p.interpreter})` : ""}`),
      h("td", { class: "wrap" }, p.args.length ? h("code", {}, p.args.join(" ")) : "–"),
      h("td", { class: "num" }, kib(p.size)),
      h("td", {}, when(p.created_at)),
      admin ? h("td", {}, p.owner) : null));
    $("#programs-table").replaceChildren(head, h("tbody", {}, rows.length ? rows :
      h("tr", { class: "empty-row" }, h("td", { colspan: cols.length }, "No programs yet."))));
    $("#programs-more").textContent = page.count > page.data.length ? `The ${page.data.length} newest of ${page.count} programs are listed.` : "";
  }

  onFile() {
    const file = $("#p-file").files[0];
    $("#err-p-file").textContent = "";
    if (!file) return;
    const name = $("#p-name");
    if (!name.value.trim() || name.value === this.autoName) {
      this.autoName = cleanName(file.name);
      name.value = this.autoName;
    }
    const ext = /\.([^.]+)$/.exec(file.name)?.[1]?.toLowerCase() || "";
    const interpreters = this.sandbox?.interpreters || [];
    if (ext === "py") {
      this.kind = "python";
    } else {
      this.kind = "executable";
      const guess = { sh: "sh", bash: "bash" }[ext];
      $("#p-interpreter").value = guess && interpreters.includes(guess) ? guess : "";
    }
    $("#p-file-desc").textContent = `${file.name}: ${kib(file.size)}` +
      (this.sandbox ? ` (at most ${kib(this.sandbox.limits.max_program_bytes)})` : "") + ".";
  }

  onKind() {
    $("#p-interpreter-field").hidden = this.kind !== "executable";
  }

  clearErrors() {
    $("#upload-error").textContent = "";
    $("#upload-done").textContent = "";
    for (const k of Object.keys(INPUTS)) $(`#err-p-${k}`).textContent = "";
    for (const el of $$("[aria-invalid]", this.form)) el.removeAttribute("aria-invalid");
  }

  /** Show a message next to its field (or at the top); returns the element to focus. */
  showError(key, message) {
    if (!key) {
      $("#upload-error").textContent = message;
      return $("#upload-error");
    }
    const target = $(`#err-p-${key}`);
    target.textContent = target.textContent ? `${target.textContent} ${message}` : message;
    const els = $$(INPUTS[key], this.form);
    for (const el of els) el.setAttribute("aria-invalid", "true");
    return els.find((el) => el.checked) || els[0];
  }

  async upload() {
    this.clearErrors();
    const file = $("#p-file").files[0];
    const max = this.sandbox?.limits?.max_program_bytes;
    const problems = [];
    if (!file) problems.push(["file", "choose the file to upload"]);
    else if (!file.size) problems.push(["file", "the file is empty"]);
    else if (max && file.size > max) problems.push(["file", `the file has ${file.size} bytes; this testbed takes at most ${max}`]);
    if (problems.length) {
      problems.map(([k, m]) => this.showError(k, m))[0]?.focus();
      return;
    }
    const kind = this.kind;
    const body = {
      name: $("#p-name").value.trim() || cleanName(file.name),
      kind,
      interpreter: kind === "executable" ? $("#p-interpreter").value || null : null,
      args: $("#p-args").value.split("\n").map((a) => a.trim()).filter((a) => a !== ""),
      content_base64: await fileBase64(file),
    };
    const button = $("#upload-button");
    button.disabled = true;
    try {
      const prog = await this.store.api.post("/api/v1/programs", body);
      toast(`Program #${prog.id} uploaded`);
      this.form.reset();
      this.autoName = "";
      this.onKind();
      $("#p-file-desc").textContent = max ? `At most ${kib(max)}.` : "";
      $("#upload-done").replaceChildren(`Uploaded program #${prog.id}: ${prog.name}, ${kib(prog.size)}. `,
        h("a", { href: `#/submit?program=${prog.id}` }, "Use it in a job"));
      await this.loadList(prog.id);
    } catch (err) {
      if (err.status === 403) {
        await this.loadSandbox(); // switched off meanwhile: the page now says so
        this.showError(null, `The server refused the upload: ${err.detail}.`);
      } else if (err.status === 422 || err.status === 413) {
        const pyd = (err.errors || []).filter((e) => Array.isArray(e.loc));
        const shown = pyd.length
          ? pyd.map((e) => this.showError(LOC_FIELD[e.loc[1]] || null, e.msg))
          : [this.showError(fieldOfUploadMessage(err.detail), err.detail)];
        shown[0]?.focus();
      } else {
        report(err, "Upload");
      }
    } finally {
      button.disabled = false;
    }
  }
}
