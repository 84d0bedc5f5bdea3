// btlog view: the page - one pane per run (tree, timeline, side panels), the moment of
// each pane, keyboard stepping (arrows by event, Shift+arrows by tick), play at 1x/10x,
// search by name/type/path, deep links (#seq=N, #tick=N, #t=12.5s; b.seq=... for the
// second run) that the URL follows, and for two runs the divergence table aligned as
// `btlog diff` aligns it. Two panes share the moment (by the runs' clocks) until one is
// sent somewhere of its own: `#t=5s` moves both, a divergence row moves each to its
// action. A moment is what btlog resolves it to (btlog.replay.moments): its seq, tick
// and time, and the last event's time apart.
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
    this.link = ["seq", String(meta.events - 1)];   // how the moment was named
    this.pending = null;
    this.busy = false;
    this.selected = null;
    this.matches = [];
    this.matchIndex = -1;
    this.root = el("div", { class: "pane", "data-run": index }, parent);
    const head = el("div", { class: "panehead" }, this.root);
    el("span", { class: "label", title: meta.file }, head, meta.label);
    el("span", { class: "muted" }, head, `${meta.final_status || "unfinished"}, ${meta.events} events`);
    this.slider = el("input", { type: "range", min: 0, max: meta.events, value: meta.events,
      "aria-label": "moment" }, head);
    this.slider.addEventListener("input", () => this.go({ count: Number(this.slider.value) }));
    this.momentText = el("span", { class: "moment" }, head);
    const body = el("div", { class: "body" }, this.root);
    const graphBox = el("div", { class: "graphbox" }, body);
    this.graph = new TreeGraph(graphBox, meta.nodes, meta.root, (uid) => this.select(uid));
    const tools = el("div", { class: "graphtools" }, graphBox);
    this.search = el("input", { type: "search", placeholder: "find a node…", title: "find by name, type or path (/); Enter: next",
      "aria-label": "find a node" }, tools);
    this.searchCount = el("span", { class: "found muted" }, tools);
    this.search.addEventListener("input", () => this.find(false));
    this.search.addEventListener("keydown", (e) => {
      e.stopPropagation();
      if (e.key === "Enter") { e.preventDefault(); this.find(true, e.shiftKey ? -1 : 1); }
      if (e.key === "Escape") { this.search.value = ""; this.find(false); this.search.blur(); }
    });
    el("button", { type: "button", title: "the whole tree, readable" }, tools, "fit")
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
      (t) => this.go({ t_ns: t }), (lo, hi) => this.loadGantt(lo, hi),
      (uid) => { this.graph.reveal(uid); this.graph.select(uid); });
    this.root.addEventListener("pointerdown", () => app.focus(this));
  }

  /** The Gantt of the timeline's window (the whole run at first). */
  async loadGantt(lo, hi) {
    const segments = await this.app.source.gantt(this.index, lo, hi);
    this.timeline.setSegments(segments, lo, hi);
  }

  /** Go to a moment: {count} (events applied), {t_ns} or {at} (any `--at` form).
   * Requests are coalesced; the other pane follows by time while the panes are linked
   * (not when `follow` is false: this pane is the one following). */
  go(request, follow = true) {
    if (request.count !== undefined) {
      request = { count: Math.max(0, Math.min(this.meta.events, Math.round(request.count))) };
      this.link = ["seq", String(request.count - 1)];
    } else if (request.t_ns !== undefined) {
      request = { t_ns: Math.max(0, Math.min(this.meta.duration_ns, request.t_ns)) };
      this.link = ["t", timeMoment(request.t_ns)];
    }
    this.target = request;
    if (follow) this.app.leader = this;
    return this.request(() => this.app.source.state(this.index, request), follow);
  }

  async request(fetchState, follow = false) {
    this.pending = [fetchState, follow];
    if (this.busy) return;
    this.busy = true;
    try {
      while (this.pending) {
        const [next, lead] = this.pending;
        this.pending = null;
        const state = await next();
        await this.show(state);
        if (lead) this.app.follow(this, state.moment);
      }
    } catch (error) {
      this.app.toast(String(error.message || error));
    } finally {
      this.busy = false;
    }
  }

  async show(state) {
    this.state = state;
    this.moment = state.moment;
    this.count = state.count;
    if (!this.pending) this.target = null;
    this.graph.update(state);
    if (state.current.length) this.graph.follow(state.current[0]);
    this.timeline.setCursor(state.moment.t_ns);
    this.timeline.follow(state.current);
    this.slider.value = state.count;
    const m = state.moment;
    const last = m.last_event_t_ns !== null && m.last_event_t_ns !== m.t_ns
      ? ` (last event ${(m.last_event_t_ns / 1e9).toFixed(3)} s)` : "";
    this.momentText.textContent = `${m.seq === null ? "before the first event" : "seq " + m.seq}` +
      ` \u00b7 tick ${m.tick} \u00b7 ${(m.t_ns / 1e9).toFixed(3)} s${last} / ` +
      `${(this.meta.duration_ns / 1e9).toFixed(1)} s`;
    this.root.setAttribute("data-count", state.count);
    this.root.setAttribute("data-seq", m.seq === null ? -1 : m.seq);
    this.root.setAttribute("data-tick", m.tick);
    this.root.setAttribute("data-t-ns", m.t_ns);
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

  /** Search: the matches as typed; Enter jumps to the next (Shift+Enter the previous):
   * the node is opened, centred and selected, and its Gantt row scrolled to. */
  find(jump, dir = 1) {
    const text = this.search.value;
    const matches = this.graph.find(text);
    if (text !== this.lastSearch) { this.matchIndex = -1; this.lastSearch = text; }
    this.matches = matches;
    for (const g of this.graph.nodeLayer.querySelectorAll("g.node.match")) g.classList.remove("match");
    this.graph.mark([], "match");
    for (const uid of matches) this.graph.elements.get(uid)?.classList.add("match");
    if (!jump || !matches.length) {
      this.searchCount.textContent = text.trim() ? `${matches.length} found` : "";
      return;
    }
    this.matchIndex = (this.matchIndex + dir + matches.length) % matches.length;
    const uid = matches[this.matchIndex];
    this.graph.reveal(uid);
    for (const m of matches) this.graph.elements.get(m)?.classList.add("match");
    this.graph.select(uid);
    this.timeline.showRow(uid);
    this.searchCount.textContent = `${this.matchIndex + 1}/${matches.length}`;
  }

  /** One event (or one tick) on from the moment last asked for, shown or not yet. */
  step(dir, byTick) {
    const moment = this.moment;
    if (byTick) {
      const tick = Math.max(0, Math.min(this.meta.last_tick, (moment ? moment.tick : 0) + dir));
      this.link = ["tick", String(tick)];
      this.app.leader = this;
      return this.request(() => this.app.source.state(this.index, { at: `tick:${tick}` }), true);
    }
    const from = this.target?.count ?? this.count;
    return this.go({ count: from + dir });
  }

  async ask(question) {
    if (!question.trim() || !this.moment) return;
    this.panels.showAsked(await this.app.source.ask(this.index, this.moment, question));
  }

  /** This pane's part of the URL fragment. */
  hashPart() {
    return `${this.prefix}${this.link[0]}=${this.link[1]}`;
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
    this.linked = false;
    this.leader = null;
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
    const panes = el("div", { class: "panes" + (info.runs.length > 1 ? " two" : "") }, this.root);
    info.runs.forEach((meta, i) => this.panes.push(new Pane(this, i, meta, panes)));
    this.focus(this.panes[0]);
    if (info.diff) this.markDivergent(info.diff);
    await this.openHash(location.hash);
    this.panes.forEach((p) => p.graph.home());
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
    if (info.runs.length > 1) {
      const label = el("label", { class: "link", title: "both runs at the same time" }, bar);
      this.linkBox = el("input", { type: "checkbox", "aria-label": "share the moment" }, label);
      label.appendChild(document.createTextNode(" share the moment"));
      this.linkBox.addEventListener("change", () => {
        this.setLinked(this.linkBox.checked);
        this.linkBox.blur();
        if (this.linked) this.follow(this.focused, this.focused.moment);
      });
    }
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

  setLinked(linked) {
    this.linked = linked && this.panes.length > 1;
    if (this.linkBox) this.linkBox.checked = this.linked;
    this.writeHash();
  }

  /** While linked, the other panes go to the moment's time in their own runs. */
  follow(leader, moment) {
    if (!this.linked || !moment) return;
    for (const pane of this.panes) {
      if (pane !== leader) pane.go({ t_ns: moment.t_ns }, false);
    }
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
          this.setLinked(false);   // each run goes to its own action
          if (row.a) this.panes[0].go({ count: row.a.seq + 1 }, false);
          if (row.b && this.panes[1]) this.panes[1].go({ count: row.b.seq + 1 }, false);
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

  /** The moment a URL fragment names for each run: [kind, value], or null. */
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

  /** Open the moments a URL fragment names. One moment for two runs links them: `#t=`
   * puts both at that time, `#seq=N` (or `#b.seq=N`) puts one there and the other at its
   * time; a moment for each unlinks them. No moment: the runs' ends. */
  async openHash(hash) {
    const moments = this.hashMoments(hash, this.info.runs);
    const named = moments.filter((m) => m !== null).length;
    this.setLinked(this.panes.length > 1 && named <= 1);
    if (this.linked && moments[0] && moments[0][0] === "t") moments[1] = moments[0];
    const leader = moments.findIndex((m) => m !== null);
    const requests = this.panes.map((pane, i) => {
      const moment = moments[i];
      if (moment === null && this.linked && leader >= 0) return null;   // follows the leader
      const at = moment === null ? "end" : momentText(moment[0], moment[1]);
      pane.link = moment === null ? ["seq", String(pane.meta.events - 1)] : moment;
      return pane.request(() => this.source.state(i, { at }).catch((error) => {
        this.toast(`#${i ? "b." : ""}${moment ? moment.join("=") : "end"}: ${error.message || error}`);
        pane.link = ["seq", String(pane.meta.events - 1)];
        return this.source.state(i, { at: "end" });
      }), i === leader);
    });
    await Promise.all(requests.filter((r) => r !== null));
    await Promise.all(this.panes.map((p) => p.busy ? new Promise((done) => {
      const wait = () => (p.busy ? setTimeout(wait, 20) : done());
      wait();
    }) : null));
  }

  writeHash() {
    if (this.panes.some((p) => !p.state)) return;
    const leader = this.leader && this.panes.includes(this.leader) ? this.leader : this.panes[0];
    const parts = this.linked ? [leader.hashPart()] : this.panes.map((p) => p.hashPart());
    if (this.linked && leader.link[0] === "t") parts[0] = `t=${leader.link[1]}`;
    const hash = "#" + parts.join("&");
    if (hash === location.hash) return;
    this.writtenHash = hash;
    history.replaceState(null, "", hash);
  }

  key(e) {
    if (e.target instanceof HTMLInputElement && ["text", "search"].includes(e.target.type)) return;
    const pane = this.focused;
    if (e.key === "ArrowRight" || e.key === "ArrowLeft") {
      e.preventDefault();
      this.stop();
      pane.step(e.key === "ArrowRight" ? 1 : -1, e.shiftKey);
    } else if (e.key === " ") {
      e.preventDefault();
      this.togglePlay();
    } else if (e.key === "Home") {
      pane.go({ count: 0 });
    } else if (e.key === "End") {
      pane.go({ count: pane.meta.events });
    } else if (e.key === "/" || (e.key === "f" && (e.ctrlKey || e.metaKey))) {
      e.preventDefault();
      pane.search.focus();
    }
  }

  togglePlay() {
    if (this.playing) { this.stop(); return; }
    const pane = this.focused;
    let t = pane.count >= pane.meta.events ? 0 : pane.moment ? pane.moment.t_ns : 0;
    let last = performance.now();
    this.playButton.textContent = "\u23f8 pause";
    this.playing = setInterval(() => {
      const now = performance.now();
      t += (now - last) * 1e6 * Number(this.speed.value);
      last = now;
      if (t >= pane.meta.duration_ns) { pane.go({ count: pane.meta.events }); this.stop(); return; }
      pane.go({ t_ns: t });
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
