// btlog view: the page - one pane per run (tree, timeline, side panels), the moment of
// each pane, keyboard stepping (arrows by event, Shift+arrows by tick), play at 1x/10x,
// deep links (#seq=N, #tick=N, #t=12.5s; b.seq=... for the second run) that the URL
// follows, and for two runs the divergence table aligned as `btlog diff` aligns them.
"use strict";

class Pane {
  /** One run's view: `index` is the run's position, `prefix` its deep-link prefix. */
  constructor(app, index, meta, parent) {
    this.app = app;
    this.index = index;
    this.meta = meta;
    this.prefix = index === 0 ? "" : "b.";
    this.nodes = new Map(meta.nodes.map((n) => [n.uid, n]));
    this.count = meta.events;
    this.state = null;
    this.pending = null;
    this.target = null;
    this.busy = false;
    this.selected = null;
    this.root = el("div", { class: "pane", "data-run": index }, parent);
    const head = el("div", { class: "panehead" }, this.root);
    el("span", { class: "label", title: meta.file }, head, meta.label);
    el("span", { class: "muted" }, head, `${meta.final_status || "unfinished"}, ${meta.events} events`);
    this.slider = el("input", { type: "range", min: 0, max: meta.events, value: meta.events,
      "aria-label": "moment" }, head);
    this.slider.addEventListener("input", () => this.moveTo(Number(this.slider.value)));
    this.momentText = el("span", { class: "moment" }, head);
    const body = el("div", { class: "body" }, this.root);
    const graphBox = el("div", { class: "graphbox" }, body);
    this.graph = new TreeGraph(graphBox, meta.nodes, meta.root, (uid) => this.select(uid));
    const tools = el("div", { class: "graphtools" }, graphBox);
    el("button", { type: "button", title: "fit the tree" }, tools, "fit")
      .addEventListener("click", () => this.graph.fit());
    el("button", { type: "button", title: "expand every subtree" }, tools, "expand all")
      .addEventListener("click", () => this.graph.expandAll());
    el("button", { type: "button", title: "show the current node" }, tools, "current")
      .addEventListener("click", () => this.state?.current.forEach((u) => this.graph.reveal(u)));
    const legend = el("div", { class: "legend" }, graphBox);
    for (const s of ["IDLE", "RUNNING", "SUCCESS", "FAILURE", "CURRENT"]) {
      const item = el("span", {}, legend);
      el("i", { class: s }, item);
      item.appendChild(document.createTextNode(s.toLowerCase()));
    }
    this.panels = new SidePanels(el("div", { class: "side" }, body), this);
    const timelineBox = el("div", { class: "timelinebox" }, this.root);
    this.timeline = new Timeline(timelineBox, meta.nodes, meta.duration_ns,
      (t) => this.moveToTime(t), (lo, hi) => this.loadGantt(lo, hi),
      (uid) => { this.graph.reveal(uid); this.graph.select(uid); });
    this.root.addEventListener("pointerdown", () => app.focus(this));
  }

  /** The Gantt of the timeline's window (the whole run at first). */
  async loadGantt(lo, hi) {
    const segments = await this.app.source.gantt(this.index, lo, hi);
    this.timeline.setSegments(segments, lo, hi);
  }

  /** Go to a moment (a count of events applied); requests are coalesced. */
  moveTo(count) {
    count = Math.max(0, Math.min(this.meta.events, Math.round(count)));
    this.target = count;
    return this.request(() => this.app.source.state(this.index, count));
  }

  moveToTime(tNs) {
    this.target = null;
    return this.request(() => this.app.source.stateAtTime(this.index, tNs));
  }

  async request(fetchState) {
    this.pending = fetchState;
    if (this.busy) return;
    this.busy = true;
    try {
      while (this.pending) {
        const next = this.pending;
        this.pending = null;
        const state = await next();
        await this.show(state);
      }
    } catch (error) {
      this.app.toast(String(error.message || error));
    } finally {
      this.busy = false;
    }
  }

  async show(state) {
    this.state = state;
    this.count = state.count;
    if (!this.pending) this.target = null;
    this.graph.update(state);
    if (state.current.length) this.graph.follow(state.current[0]);
    this.timeline.setCursor(state.t_ns);
    this.slider.value = state.count;
    const seq = state.count - 1;
    this.momentText.textContent = `seq ${seq} \u00b7 tick ${state.tick} \u00b7 ` +
      `${(state.t_ns / 1e9).toFixed(3)} s / ${(this.meta.duration_ns / 1e9).toFixed(1)} s`;
    this.root.setAttribute("data-count", state.count);
    this.panels.showAnswers(state.answers);
    this.panels.showBlackboard(state.blackboard);
    this.panels.showNode(this.selected, state);
    this.panels.showEvents(state.events, state.count);
    this.app.writeHash();
    this.root.setAttribute("data-ready", "1");
  }

  select(uid) {
    this.selected = uid;
    if (this.state) this.panels.showNode(uid, this.state);
  }

  /** One event (or one tick) on from the moment last asked for, shown or not yet. */
  async step(dir, byTick) {
    const from = this.target ?? this.count;
    if (byTick) return this.moveTo(await this.app.source.step(this.index, from, dir));
    return this.moveTo(from + dir);
  }

  async ask(question) {
    if (!question.trim()) return;
    this.panels.showAsked(await this.app.source.ask(this.index, this.count, question));
  }

  /** This pane's part of the URL fragment. */
  hashPart() {
    return `${this.prefix}seq=${this.count - 1}`;
  }
}

class App {
  constructor(root) {
    this.root = root;
    this.source = makeSource();
    this.panes = [];
    this.focused = null;
    this.playing = null;
    this.writtenHash = null;
  }

  async start() {
    const info = await this.source.init();
    this.info = info;
    this.root.className = "";
    this.root.replaceChildren();
    this.buildTopbar(info);
    if (info.report) {
      const details = el("details", { class: "diff report" }, this.root);
      el("summary", {}, details, info.report.split("\n")[0] + " — the check's report");
      el("pre", {}, details, info.report);
    }
    if (info.diff) this.buildDiff(info.diff);
    // The moments are asked for first: the answers arrive while the panes are drawn.
    const moments = this.hashMoments(location.hash, info.runs);
    const states = moments.map((moment, i) => this.momentState(i, moment));
    const panes = el("div", { class: "panes" + (info.runs.length > 1 ? " two" : "") }, this.root);
    info.runs.forEach((meta, i) => this.panes.push(new Pane(this, i, meta, panes)));
    this.focus(this.panes[0]);
    if (info.diff) this.markDivergent(info.diff);
    await Promise.all(this.panes.map((pane, i) => pane.request(() => states[i])));
    this.panes.forEach((p) => p.graph.home(p.state?.current[0]));
    this.panes.forEach((p) => p.loadGantt());
    window.addEventListener("hashchange", () => {
      if (location.hash !== this.writtenHash) this.openHash(location.hash);
    });
    document.addEventListener("keydown", (e) => this.key(e));
    this.root.setAttribute("data-loaded", "1");
  }

  buildTopbar(info) {
    const bar = el("div", { class: "topbar" }, this.root);
    el("h1", {}, bar, "btlog view");
    const back = el("button", { type: "button", title: "previous event (\u2190)" }, bar, "\u25c0");
    this.playButton = el("button", { type: "button", title: "play / pause (space)", class: "play" },
      bar, "\u25b6 play");
    const next = el("button", { type: "button", title: "next event (\u2192)" }, bar, "\u25b6");
    this.speed = el("select", { "aria-label": "speed" }, bar);
    for (const s of ["1", "10"]) el("option", { value: s }, this.speed, `${s}\u00d7`);
    el("span", { class: "hint" }, bar,
      "\u2190/\u2192 event \u00b7 Shift+\u2190/\u2192 tick \u00b7 space play \u00b7 drag the timeline to " +
      "scrub, wheel on it to zoom, click a row's name to find the node");
    // The keyboard belongs to the moment: a clicked button or the speed list lets go of the
    // focus, so that space and the arrows do not press or change them as well.
    for (const control of [back, this.playButton, next]) {
      control.addEventListener("click", () => control.blur());
    }
    this.speed.addEventListener("change", () => this.speed.blur());
    back.addEventListener("click", () => this.focused.step(-1, false));
    next.addEventListener("click", () => this.focused.step(1, false));
    this.playButton.addEventListener("click", () => this.togglePlay());
    for (const w of info.runs.flatMap((r) => r.warnings)) this.toast(w);
  }

  buildDiff(diff) {
    const box = el("div", { class: "diff" }, this.root);
    el("div", {}, box,
      `Divergence (as btlog diff aligns it): edit distance ${diff.edit_distance}` +
      (diff.identical ? " - identical" : ""));
    const table = el("table", {}, box);
    const head = el("tr", {}, table);
    for (const h of ["A: " + diff.a, "", "B: " + diff.b]) el("th", {}, head, h);
    for (const sub of diff.subgoals) {
      const tr = el("tr", {}, table);
      el("th", { class: "subgoal", colspan: 3 }, tr,
        `${sub.subgoal} (edit distance ${sub.edit_distance})`);
      for (const row of sub.rows) {
        const r = el("tr", { class: "row" + (row.op === "equal" ? "" : " divergent") }, table);
        el("td", {}, r, row.a ? row.a.action : "");
        el("td", {}, r, row.op === "equal" ? "=" : row.op === "only_a" ? "\u2190 only A" : "only B \u2192");
        el("td", {}, r, row.b ? row.b.action : "");
        r.addEventListener("click", () => {
          if (row.a) this.panes[0].moveTo(row.a.seq + 1);
          if (row.b && this.panes[1]) this.panes[1].moveTo(row.b.seq + 1);
        });
      }
    }
  }

  markDivergent(diff) {
    for (const sub of diff.subgoals) {
      for (const d of sub.divergent) {
        const pane = this.panes[d.side === "a" ? 0 : 1];
        if (pane) pane.graph.mark([d.uid], "divergent");
      }
    }
  }

  focus(pane) {
    if (this.focused) this.focused.root.classList.remove("focused");
    this.focused = pane;
    pane.root.classList.add("focused");
  }

  /** The moment a URL fragment names for each run: [kind, value], or null (its end). */
  hashMoments(hash, runs) {
    const parts = new Map();
    for (const piece of hash.replace(/^#/, "").split("&")) {
      const at = piece.indexOf("=");
      if (at > 0) parts.set(decodeURIComponent(piece.slice(0, at)), decodeURIComponent(piece.slice(at + 1)));
    }
    return runs.map((meta, index) => {
      const prefix = index === 0 ? "" : "b.";
      const kind = ["seq", "tick", "t"].find((k) => parts.has(prefix + k));
      return kind === undefined ? null : [kind, parts.get(prefix + kind)];
    });
  }

  /** The state at a run's deep-linked moment (its end, with a message, when unknown). */
  momentState(index, moment) {
    const end = () => this.source.state(index, this.info.runs[index].events);
    if (moment === null) return end();
    return this.source.stateAt(index, moment[0], moment[1]).catch((error) => {
      this.toast(`#${index ? "b." : ""}${moment[0]}=${moment[1]}: ${error.message || error}`);
      return end();
    });
  }

  /** Open the moments a URL fragment names. */
  async openHash(hash) {
    const moments = this.hashMoments(hash, this.info.runs);
    await Promise.all(this.panes.map((pane, i) => pane.request(() => this.momentState(i, moments[i]))));
  }

  writeHash() {
    const hash = "#" + this.panes.map((p) => p.hashPart()).join("&");
    if (hash === location.hash) return;
    this.writtenHash = hash;
    history.replaceState(null, "", hash);
  }

  key(e) {
    if (e.target instanceof HTMLInputElement && e.target.type === "text") return;
    const pane = this.focused;
    if (e.key === "ArrowRight" || e.key === "ArrowLeft") {
      e.preventDefault();
      this.stop();
      pane.step(e.key === "ArrowRight" ? 1 : -1, e.shiftKey);
    } else if (e.key === " ") {
      e.preventDefault();
      this.togglePlay();
    } else if (e.key === "Home") {
      pane.moveTo(0);
    } else if (e.key === "End") {
      pane.moveTo(pane.meta.events);
    }
  }

  togglePlay() {
    if (this.playing) { this.stop(); return; }
    const pane = this.focused;
    if (pane.count >= pane.meta.events) pane.moveTo(0);
    let t = pane.count >= pane.meta.events ? 0 : pane.state ? pane.state.t_ns : 0;
    let last = performance.now();
    this.playButton.textContent = "\u23f8 pause";
    this.playing = setInterval(() => {
      const now = performance.now();
      t += (now - last) * 1e6 * Number(this.speed.value);
      last = now;
      if (t >= pane.meta.duration_ns) { pane.moveTo(pane.meta.events); this.stop(); return; }
      pane.moveToTime(t);
    }, 100);
  }

  stop() {
    if (!this.playing) return;
    clearInterval(this.playing);
    this.playing = null;
    this.playButton.textContent = "\u25b6 play";
  }

  toast(message) {
    const t = el("div", { class: "toast", role: "status" }, document.body, message);
    setTimeout(() => t.remove(), 4000);
  }
}

window.addEventListener("DOMContentLoaded", () => {
  const app = new App(document.getElementById("app"));
  window.btlogViewer = app;
  app.start().catch((error) => {
    const root = document.getElementById("app");
    root.className = "error";
    root.textContent = `btlog view could not start: ${error.message || error}`;
  });
});
