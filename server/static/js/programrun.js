// The experiment page's panel for a job planned by an uploaded program: which program, how it
// ended (planning_info.program: exit code or signal, time limit, wall and CPU time, dropped
// output, isolation), why the job failed, and the program's log: the messages with direction
// "o" (stdout), "e" (stderr) and "s" (the sandbox, with the robot-port conversation) of the run
// that executed it, styled apart and filterable.

import { saveBlob } from "./api.js";
import { TERMINAL, h, num, report } from "./dom.js";

const KINDS = [
  // key, label for the filter, tag shown on each line
  ["stdout", "stdout", "out"],
  ["stderr", "stderr", "err"],
  ["port", "robot port", "port"],
  ["sandbox", "sandbox", "sandbox"],
];
const TAG = Object.fromEntries(KINDS.map(([k, , t]) => [k, t]));
const PAGE = 10000; // the messages endpoint's largest page
const MAX_PAGES = 20;
const SIGNALS = { 1: "SIGHUP", 2: "SIGINT", 4: "SIGILL", 6: "SIGABRT", 7: "SIGBUS", 8: "SIGFPE", 9: "SIGKILL",
  11: "SIGSEGV", 13: "SIGPIPE", 14: "SIGALRM", 15: "SIGTERM", 24: "SIGXCPU", 25: "SIGXFSZ", 31: "SIGSYS" };

/** Which kind of log line a message is; null for the robot's protocol lines ("<", ">"). */
export function lineKind(m) {
  if (m.direction === "o") return "stdout";
  if (m.direction === "e") return "stderr";
  if (m.direction === "s") return /^robot port [<>] /.test(m.line) ? "port" : "sandbox";
  return null;
}

/** "exit code 3", "killed by signal SIGSEGV (11)", or "stopped by the sandbox". */
export function howItEnded(info) {
  let text;
  if (info.exit_code != null) text = `exit code ${info.exit_code}`;
  else if (info.signal != null) {
    const name = typeof info.signal === "number" ? SIGNALS[info.signal] : String(info.signal);
    text = `killed by signal ${name ? `${name}${typeof info.signal === "number" ? ` (${info.signal})` : ""}` : info.signal}`;
  } else text = "stopped by the sandbox";
  return text;
}

function bytes(n) {
  return !n ? "none" : n >= 1024 ? `${num(n / 1024, 1)} KiB` : `${n} bytes`;
}

function isolation(iso) {
  if (!iso) return "–";
  const parts = [(iso.namespaces || []).length ? `namespaces ${iso.namespaces.join(" + ")}` : "no namespaces"];
  if (iso.user_namespace) parts.push("user namespace");
  parts.push(iso.own_uid ? "a uid of its own" : "the server's uid");
  if (iso.proc) parts.push(`/proc ${iso.proc}`);
  parts.push(iso.server_files_hidden ? "server files hidden" : "server files not hidden");
  parts.push(iso.seccomp ? "seccomp" : "no seccomp");
  return parts.join(", ");
}

export class ProgramPanel {
  constructor(store) {
    this.store = store;
    this.hidden = new Set(); // kinds filtered out
    this.log = null; // {key, runId, lines: [{kind, line}]}
    this.asked = new Set(); // program ids looked up by id
    this.facts = h("dl", { class: "facts" });
    this.reason = h("p", { class: "program-reason" });
    this.logHead = h("div", { class: "log-head" });
    this.logBody = h("div", {});
    this.el = h("section", { class: "panel program-panel", id: "program-panel", "aria-labelledby": "program-title", hidden: true },
      h("h2", { id: "program-title" }, "Uploaded program"), this.facts, this.reason, this.logHead, this.logBody);
  }

  /** The program's name and details, when known (planning_info or the program list). */
  program(d) {
    const known = this.store.programs.get(d.program);
    if (!known && !this.asked.has(d.program)) {
      this.asked.add(d.program);
      this.store.api.get(`/api/v1/programs/${d.program}`).then((p) => {
        this.store.notePrograms([p]);
        if (this.d?.id === d.id) this.render(this.d);
      }).catch(() => { /* gone or not ours: planning_info still names it */ });
    }
    return known || null;
  }

  /** Fetch the log of the run that executed the program, once it ran (again when the job ends). */
  async load(d) {
    const info = d.planning_info?.program;
    if (d.program == null || !info || info.run_id == null) return;
    const key = `${info.run_id}:${TERMINAL.has(d.status)}`;
    if (this.log?.key === key) return;
    const lines = [];
    for (let page = 0; page < MAX_PAGES; page++) {
      const res = await this.store.api.get(`/api/v1/runs/${info.run_id}/messages?offset=${page * PAGE}&limit=${PAGE}`);
      for (const m of res.data) {
        const kind = lineKind(m);
        if (kind) lines.push({ kind, line: m.line });
      }
      const last = res.data[res.data.length - 1];
      // the program's lines come together: stop once a page ends past them
      if (!last || !lineKind(last) || (page + 1) * PAGE >= res.count) break;
    }
    this.log = { key, runId: info.run_id, lines };
    this.logKey = null;
  }

  render(d) {
    this.d = d;
    this.el.hidden = d.program == null;
    if (d.program == null) return;
    const info = d.planning_info?.program || null;
    const p = this.program(d);
    const name = info?.name || p?.name || null;
    const run = info?.run_id != null ? d.runs.find((r) => r.id === info.run_id) : null;
    const facts = [
      ["Program", `${name ?? "program"} (#${d.program})`],
      ["Kind", p ? (p.kind === "python" ? "Python" : `executable${p.interpreter ? ` run by ${p.interpreter}` : ""}`) : "–"],
      ["Arguments", p ? (p.args.length ? p.args.join(" ") : "none") : "–"],
    ];
    if (info) {
      facts.push(
        ["Ended with", howItEnded(info)],
        ["Timed out", info.timed_out ? "yes" : "no"],
        ["Wall time", info.wall_s == null ? "–" : `${num(info.wall_s, 2)} s`],
        ["CPU time", info.cpu_s == null ? "–" : `${num(info.cpu_s, 2)} s`],
        ["Peak memory", info.max_rss_kib == null ? "–" : `${num(info.max_rss_kib / 1024, 1)} MiB`],
        ["Processes (most at once)", info.processes_max ?? "–"],
        ["Dropped output", `stdout ${bytes(info.stdout_dropped_bytes)}, stderr ${bytes(info.stderr_dropped_bytes)}`],
        ["Isolation", isolation(info.isolation)],
        ["Executed in", run ? `run ${run.id} (${run.mode} #${run.repetition})` : `run ${info.run_id ?? "–"}`],
        ["Path", d.planned_path ? `${d.planned_path.length} points received` : "none accepted"],
      );
    } else {
      facts.push(["Ran", TERMINAL.has(d.status) ? "no" : "not yet: it runs when the first run is planned"]);
    }
    this.facts.replaceChildren(...facts.map(([k, v]) => h("div", { dataset: { fact: k } }, h("dt", {}, k), h("dd", {}, v))));
    const failed = d.status === "failed" || d.status === "error";
    const why = failed ? (run?.error || d.error) : "";
    this.reason.replaceChildren(...(why ? [h("strong", {}, "Why it failed: "), why] : []));
    this.renderLog(info);
  }

  renderLog(info) {
    const key = this.log ? `${this.log.key}:${this.log.lines.length}` : info ? "loading" : "none";
    if (key === this.logKey) return;
    this.logKey = key;
    if (!this.log) {
      this.logHead.replaceChildren();
      this.logBody.replaceChildren(info ? h("p", { class: "muted small" }, "Loading the program's log…") : "");
      return;
    }
    const { runId, lines } = this.log;
    const counts = Object.fromEntries(KINDS.map(([k]) => [k, lines.filter((l) => l.kind === k).length]));
    this.logHead.replaceChildren(
      h("h3", { id: "program-log-title" }, `Log (run ${runId})`),
      h("div", { class: "legend", role: "group", "aria-label": "Log lines shown" },
        ...KINDS.map(([k, label]) => h("label", { class: "check" },
          h("input", { type: "checkbox", checked: !this.hidden.has(k), dataset: { kind: k }, onchange: (ev) => {
            if (ev.target.checked) this.hidden.delete(k); else this.hidden.add(k);
            this.renderLines();
          } }), h("span", { class: `tag log-${k}` }, TAG[k]), `${label} (${counts[k]})`)),
        h("button", { type: "button", class: "small", onclick: () => this.download() }, "Download log (text)")),
    );
    this.list = h("ol", { class: "program-log", id: "program-log", tabindex: 0, "aria-labelledby": "program-log-title" });
    this.logBody.replaceChildren(this.list);
    this.renderLines();
  }

  renderLines() {
    const shown = this.log.lines.filter((l) => !this.hidden.has(l.kind));
    this.list.replaceChildren(...(shown.length ? shown.map((l) => h("li", { class: `log-${l.kind}` },
      h("span", { class: `tag log-${l.kind}` }, TAG[l.kind]), h("span", { class: "text" }, l.line))) :
      [h("li", { class: "empty" }, this.log.lines.length ? "No lines of the kinds chosen." : "The program printed nothing.")]));
  }

  download() {
    if (!this.log) return;
    try {
      const text = this.log.lines.map((l) => `[${TAG[l.kind]}] ${l.line}`).join("\n") + "\n";
      saveBlob(new Blob([text], { type: "text/plain" }), `run-${this.log.runId}-program.log`);
    } catch (err) {
      report(err, "Download");
    }
  }
}
