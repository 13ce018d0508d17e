// REST client and the live event stream, both with `Authorization: Bearer <token>`.
//
// The stream is read with fetch() and a ReadableStream rather than EventSource:
// EventSource cannot send headers, and putting the token in the URL would leak
// it into access logs and browser history.  The parser below implements the
// parts of the server-sent-events format the server uses (event, data, retry,
// comments) and reconnects with back-off; while it is down the app polls.

export class ApiError extends Error {
  /** status 0: the server could not be reached. */
  constructor(status, detail, errors = []) {
    super(detail);
    this.name = "ApiError";
    this.status = status;
    this.detail = detail;
    this.errors = errors;
  }
}

export class Api {
  constructor(token) {
    this.token = token;
  }

  headers(extra = {}) {
    return { Authorization: `Bearer ${this.token}`, ...extra };
  }

  async request(method, path, body, { signal, raw = false } = {}) {
    let res;
    try {
      res = await fetch(path, {
        method,
        signal,
        cache: "no-store",
        headers: this.headers(body === undefined ? {} : { "Content-Type": "application/json" }),
        body: body === undefined ? undefined : JSON.stringify(body),
      });
    } catch (err) {
      if (err.name === "AbortError") throw err;
      throw new ApiError(0, "Cannot reach the server");
    }
    if (!res.ok) {
      let detail = `${res.status} ${res.statusText}`;
      let errors = [];
      try {
        const j = await res.json();
        if (j && j.detail !== undefined) detail = typeof j.detail === "string" ? j.detail : JSON.stringify(j.detail);
        if (j && Array.isArray(j.errors)) errors = j.errors;
      } catch {
        /* not JSON: keep the status line */
      }
      throw new ApiError(res.status, detail, errors);
    }
    return raw ? res : res.json();
  }

  get(path, opts) {
    return this.request("GET", path, undefined, opts);
  }

  post(path, body = {}, opts) {
    return this.request("POST", path, body, opts);
  }

  /** Fetch with the token and hand the body to the browser as a file. */
  async download(path, filename) {
    const res = await this.request("GET", path, undefined, { raw: true });
    saveBlob(await res.blob(), filename);
  }
}

export function saveBlob(blob, filename) {
  const url = URL.createObjectURL(blob);
  const a = document.createElement("a");
  a.href = url;
  a.download = filename;
  a.hidden = true;
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 30000);
}

const sleep = (ms, signal) =>
  new Promise((resolve) => {
    const t = setTimeout(resolve, ms);
    signal?.addEventListener("abort", () => { clearTimeout(t); resolve(); }, { once: true });
  });

/**
 * The server's event stream.  onEvent(type, data) for every event; onState(state) with
 * "connecting" | "live" | "polling" | "unauthorized" | "stopped".
 */
export class EventStream {
  constructor(api, { onEvent, onState, path = "/api/v1/events" }) {
    this.api = api;
    this.onEvent = onEvent;
    this.onState = onState;
    this.path = path;
    this.retry = 2000;
    this.ctrl = null;
    this.state = "stopped";
  }

  start() {
    if (this.ctrl) return;
    this.ctrl = new AbortController();
    this.loop(this.ctrl.signal).catch(() => {});
  }

  stop() {
    this.ctrl?.abort();
    this.ctrl = null;
    this.setState("stopped");
  }

  setState(s) {
    if (s === this.state) return;
    this.state = s;
    try { this.onState?.(s); } catch { /* a view's problem must not kill the stream */ }
  }

  async loop(signal) {
    let failures = 0;
    while (!signal.aborted) {
      this.setState(failures ? "polling" : "connecting");
      try {
        const res = await fetch(this.path, {
          signal, cache: "no-store", headers: this.api.headers({ Accept: "text/event-stream" }),
        });
        if (res.status === 401) {
          this.setState("unauthorized");
          return;
        }
        if (!res.ok || !res.body) throw new Error(`HTTP ${res.status}`);
        this.setState("live");
        failures = 0;
        await this.read(res.body, signal);
      } catch {
        if (signal.aborted) return;
      }
      failures += 1;
      this.setState("polling");
      await sleep(Math.min(this.retry * 2 ** Math.min(failures - 1, 3), 15000), signal);
    }
  }

  async read(body, signal) {
    const reader = body.pipeThrough(new TextDecoderStream()).getReader();
    signal.addEventListener("abort", () => reader.cancel().catch(() => {}), { once: true });
    let buf = "";
    for (;;) {
      const { value, done } = await reader.read();
      if (done) return;
      buf += value;
      if (buf.includes("\r") && !buf.endsWith("\r")) buf = buf.replace(/\r\n?/g, "\n");
      let i;
      while ((i = buf.indexOf("\n\n")) >= 0) {
        const block = buf.slice(0, i);
        buf = buf.slice(i + 2);
        this.dispatch(block);
      }
    }
  }

  dispatch(block) {
    let type = "message";
    const data = [];
    for (const line of block.split("\n")) {
      if (!line || line.startsWith(":")) continue;
      const c = line.indexOf(":");
      const field = c < 0 ? line : line.slice(0, c);
      let value = c < 0 ? "" : line.slice(c + 1);
      if (value.startsWith(" ")) value = value.slice(1);
      if (field === "event") type = value;
      else if (field === "data") data.push(value);
      else if (field === "retry" && /^\d+$/.test(value)) this.retry = Math.max(500, Number(value));
    }
    if (!data.length) return;
    let payload;
    try {
      payload = JSON.parse(data.join("\n"));
    } catch {
      return;
    }
    try {
      this.onEvent(type, payload);
    } catch (err) {
      console.warn("event handler failed", err);
    }
  }
}
