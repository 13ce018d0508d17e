// Entry point: token login, hash routing (#/field, #/experiments, #/experiments/ID, #/compare?ids=1,2,
// #/submit[?program=ID], #/programs),
// and the shared store that keeps live data.

import { Api, ApiError } from "./api.js";
import { ComparePage } from "./compare.js";
import { $, $$, loadVocabulary, report } from "./dom.js";
import { ExperimentPage, ExperimentsPage } from "./experiments.js";
import { FieldPage } from "./live.js";
import { ProgramsPage } from "./programs.js";
import { Store } from "./store.js";
import { SubmitPage } from "./submit.js";

const TOKEN_KEY = "twb.token";
const VIEWS = ["login", "field", "experiments", "experiment", "compare", "submit", "programs"];

const app = {
  store: null,
  pages: null,
  started: false,
};

function savedToken() {
  return sessionStorage.getItem(TOKEN_KEY) || localStorage.getItem(TOKEN_KEY) || "";
}

function forgetToken() {
  sessionStorage.removeItem(TOKEN_KEY);
  localStorage.removeItem(TOKEN_KEY);
}

/** Check a token against /users/me; returns the user or throws ApiError. */
async function whoAmI(token) {
  return new Api(token).get("/api/v1/users/me");
}

function showView(name) {
  for (const v of VIEWS) $(`#view-${v}`).hidden = v !== name;
  const navName = name === "experiment" || name === "compare" ? "experiments" : name;
  for (const a of $$("#nav a")) {
    if (a.dataset.view === navName) a.setAttribute("aria-current", "page");
    else a.removeAttribute("aria-current");
  }
}

function loginMessage(err) {
  if (err instanceof ApiError) {
    if (err.status === 401) return `The server refused this token (${err.detail}). Check it and try again.`;
    if (err.status === 403) return `This token cannot be used here: ${err.detail}`;
    if (err.status === 0) return "Cannot reach the server. Is `twb up` running?";
    return `Login failed: ${err.detail}`;
  }
  return `Login failed: ${err && err.message ? err.message : err}`;
}

function showLogin(message = "") {
  stopSession();
  $("#nav").hidden = true;
  $("#session").hidden = true;
  showView("login");
  $("#login-error").textContent = message;
  const input = $("#login-token");
  input.setAttribute("aria-invalid", message ? "true" : "false");
  document.title = "Log in · Teleworkbench";
  input.focus();
}

function stopSession() {
  if (app.store) app.store.stop();
  app.store = null;
  app.pages = null;
}

function startSession(token, user) {
  if (app.started) {
    // views bind to the page once; a second login in the same page starts afresh
    location.reload();
    return;
  }
  app.started = true;
  stopSession();
  const store = new Store(new Api(token));
  store.user = user;
  app.store = store;
  app.pages = {
    field: new FieldPage(store),
    experiments: new ExperimentsPage(store),
    experiment: new ExperimentPage(store),
    compare: new ComparePage(store),
    submit: new SubmitPage(store, { onSubmitted: (id) => { location.hash = `#/experiments/${id}`; } }),
    programs: new ProgramsPage(store),
  };
  store.addEventListener("stream", (e) => {
    const el = $("#stream-state");
    const text = { live: "live", polling: "polling", connecting: "connecting", stopped: "offline", unauthorized: "logged out" }[e.detail] || e.detail;
    el.textContent = text;
    el.className = `stream ${e.detail}`;
    el.title = e.detail === "live" ? "Live events from the server" : "Event stream down: refreshing by polling";
  });
  store.addEventListener("unauthorized", () => {
    forgetToken();
    showLogin("Your token is no longer accepted. Log in again.");
  });
  $("#user-name").textContent = `${user.name}${user.is_admin ? " (admin)" : ""}`;
  $("#nav").hidden = false;
  $("#session").hidden = false;
  store.start();
  route();
}

async function login(ev) {
  ev.preventDefault();
  const token = $("#login-token").value.trim();
  const remember = $("#login-remember").checked;
  if (!token) {
    $("#login-error").textContent = "Enter a token.";
    $("#login-token").setAttribute("aria-invalid", "true");
    $("#login-token").focus();
    return;
  }
  const button = $("#login-form button[type=submit]");
  button.disabled = true;
  try {
    const user = await whoAmI(token);
    forgetToken();
    (remember ? localStorage : sessionStorage).setItem(TOKEN_KEY, token);
    $("#login-token").value = "";
    $("#login-error").textContent = "";
    if (!location.hash || location.hash === "#/login") location.hash = "#/field";
    startSession(token, user);
  } catch (err) {
    showLogin(loginMessage(err));
    $("#login-token").value = token;
    $("#login-token").select();
  } finally {
    button.disabled = false;
  }
}

function route() {
  if (!app.store) return;
  const [hash, query = ""] = (location.hash || "#/field").split("?");
  const parts = hash.replace(/^#\/?/, "").split("/");
  const { pages } = app;
  pages.experiments.hide();
  if (parts[0] === "experiments" && parts[1] && /^\d+$/.test(parts[1])) {
    const id = Number(parts[1]);
    showView("experiment");
    document.title = `Experiment ${id} · Teleworkbench`;
    pages.experiment.show(id);
    return;
  }
  pages.experiment.hide();
  if (parts[0] === "compare") {
    const ids = (new URLSearchParams(query).get("ids") || "").split(",").filter((x) => /^\d+$/.test(x)).map(Number);
    showView("compare");
    document.title = "Compare · Teleworkbench";
    pages.compare.show(ids);
    return;
  }
  if (parts[0] === "experiments") {
    showView("experiments");
    document.title = "Experiments · Teleworkbench";
    pages.experiments.show();
  } else if (parts[0] === "submit") {
    showView("submit");
    document.title = "Submit · Teleworkbench";
    pages.submit.show(new URLSearchParams(query));
  } else if (parts[0] === "programs") {
    showView("programs");
    document.title = "Programs · Teleworkbench";
    pages.programs.show().catch((err) => report(err, "Programs"));
  } else {
    showView("field");
    document.title = "Field · Teleworkbench";
    pages.field.show();
  }
}

async function boot() {
  await loadVocabulary();
  $("#login-form").addEventListener("submit", (ev) => login(ev).catch((err) => report(err, "Login")));
  $("#logout").addEventListener("click", () => {
    forgetToken();
    showLogin("Logged out.");
  });
  window.addEventListener("hashchange", () => {
    route();
    $("#main").focus({ preventScroll: true });
  });
  const token = savedToken();
  if (!token) return showLogin();
  try {
    startSession(token, await whoAmI(token));
  } catch (err) {
    if (err instanceof ApiError && err.status === 401) forgetToken();
    showLogin(loginMessage(err));
  }
}

boot().catch((err) => report(err, "Start-up"));
