// btlog view: where the data comes from.
// ServerSource asks `btlog view`'s server (the read model); EmbeddedSource folds the
// events of an exported page in the browser. Both answer the same calls with the same
// shapes, so the rest of the page does not know which one it has.
"use strict";

const STATUS_NAMES = ["IDLE", "RUNNING", "SUCCESS", "FAILURE", "SKIPPED"];

/** The number of values in a sorted array that are at most x. */
function upperBound(values, x) {
  let lo = 0, hi = values.length;
  while (lo < hi) {
    const mid = (lo + hi) >> 1;
    if (values[mid] <= x) lo = mid + 1; else hi = mid;
  }
  return lo;
}

/** Recognise a question as `btlog ask` does (its own patterns, sent by btlog). */
function questionIntent(patterns, question) {
  const text = question.trim().toLowerCase().replace(/\u2019/g, "'").split(/\s+/).join(" ")
    .replace(/[?!. ]+$/, "");
  for (const [intent, source] of patterns) {
    const match = new RegExp(source).exec(text);
    if (match) return intent;
  }
  return null;
}

/** A deep link's moment in the form `--at` takes. */
function momentText(kind, value) {
  return kind === "seq" ? `seq:${value}` : kind === "tick" ? `tick:${value}` : value;
}

/** A time since the start as a moment, exact and short ("8.4s"), as btlog writes it. */
function timeMoment(tNs) {
  const ns = Math.max(0, Math.round(tNs));
  const whole = Math.floor(ns / 1e9), fraction = String(ns % 1e9).padStart(9, "0").replace(/0+$/, "");
  return fraction ? `${whole}.${fraction}s` : `${whole}s`;
}

/** The query of a moment request: {count}, {t_ns} or {at} (any `--at` form). */
function momentQuery(request) {
  if (request.at !== undefined) return `at=${encodeURIComponent(request.at)}`;
  if (request.t_ns !== undefined) return `t_ns=${Math.round(request.t_ns)}`;
  return `count=${request.count}`;
}

class ServerSource {
  /** The page served by `btlog view`: every question goes to the server. */
  async init() {
    this.info = await this.get("/api/runs");
    return this.info;
  }
  async get(url) {
    const response = await fetch(url);
    const data = await response.json();
    if (!response.ok) throw new Error(data.error || response.statusText);
    return data;
  }
  state(run, request) { return this.get(`/api/run/${run}/state?${momentQuery(request)}`); }
  gantt(run, lo, hi) {
    const window = lo === undefined ? "" : `?lo=${Math.floor(lo)}&hi=${Math.ceil(hi)}`;
    return this.get(`/api/run/${run}/gantt${window}`);
  }
  ask(run, moment, question) {
    return this.get(`/api/run/${run}/ask?count=${moment.count}&t_ns=${moment.t_ns}` +
      `&at=${encodeURIComponent(moment.at)}&q=${encodeURIComponent(question)}`);
  }
}

class EmbeddedRun {
  /** One exported run: its events as columns, folded here on demand. */
  constructor(data) {
    this.meta = data.meta;
    const ev = data.events;
    this.t = ev.t; this.tick = ev.tick; this.kind = ev.kind; this.uid = ev.uid;
    this.st = ev.st; this.prev = ev.prev; this.writes = ev.writes;
    // {at: [count...], sets: [{answers: [index...], current: [uid...]}...], table: [answer...]}:
    // each distinct answer once in the table (without "nodes" when they are the set's current
    // nodes), the sets refer to it (answersAt resolves them)
    this.answers = data.answers;
    this.ticks = data.ticks;              // {tick: [...], start: [...], end: [...]}
    this.every = 1024;
    let maxUid = 0;
    for (const n of this.meta.nodes) maxUid = Math.max(maxUid, n.uid);
    this.size = maxUid + 1;
    this.snapshots = [];                  // status codes before event k * every
    const status = new Uint8Array(this.size);
    for (let i = 0; i < this.t.length; i++) {
      if (i % this.every === 0) this.snapshots.push(status.slice());
      if (this.kind[i] === 0) status[this.uid[i]] = this.st[i];
    }
    this.snapshots.push(status.slice());
    this.writeSeqs = [];
    for (let i = 0; i < this.t.length; i++) if (this.kind[i] === 1) this.writeSeqs.push(i);
  }
  statusAt(count) {
    const k = Math.floor(count / this.every);
    const status = this.snapshots[k].slice();
    for (let i = k * this.every; i < count; i++) {
      if (this.kind[i] === 0) status[this.uid[i]] = this.st[i];
    }
    return status;
  }
  /** A moment resolved as btlog.replay.moments resolves it: the same count, seq, tick,
   * time and last event's time (tests/test_view_browser.py compares the two). */
  resolve(text) {
    const n = this.t.length, s = String(text).trim().toLowerCase();
    const lastTime = (count) => (count ? this.t[count - 1] : null);
    const made = (count, tNs, tick) => ({ at: String(text), count, seq: count ? count - 1 : null,
      t_ns: tNs, tick, last_event_t_ns: lastTime(count) });
    if (s === "seq:-1") return made(0, 0, 0);
    if (s === "end") return made(n, this.meta.duration_ns, this.meta.last_tick);
    let m = /^seq\s*:\s*(\d+)$/.exec(s);
    if (m) {
      const seq = Number(m[1]);
      if (seq >= n) throw new Error(`moment '${text}' is after the end of the run (last event seq:${n - 1})`);
      return { ...made(seq + 1, this.t[seq], this.tick[seq]) };
    }
    m = /^tick\s*:\s*(\d+)$/.exec(s);
    if (m) {
      const tick = Number(m[1]);
      if (tick > this.meta.last_tick) {
        throw new Error(`moment '${text}' is after the end of the run (last tick ${this.meta.last_tick})`);
      }
      const count = upperBound(this.tick, tick);
      const index = upperBound(this.ticks.tick, tick) - 1;
      const end = index >= 0 ? this.ticks.end[index] : 0;
      return made(count, Math.max(end, lastTime(count) ?? 0), tick);
    }
    const t = exactTime(s);
    if (t === null) throw new Error(`unparseable moment '${text}' (this page takes seconds, -2s, tick:N, seq:N, end)`);
    const tNs = t < 0 || s.startsWith("-") ? this.meta.duration_ns - Math.abs(t) : t;
    if (tNs < 0) throw new Error(`moment '${text}' is before the start of the run`);
    if (tNs > this.meta.duration_ns) throw new Error(`moment '${text}' is after the end of the run`);
    const index = upperBound(this.ticks.start, tNs) - 1;
    return made(upperBound(this.t, tNs), tNs, index >= 0 ? this.ticks.tick[index] : 0);
  }
  state(moment) {
    const count = moment.count;
    const codes = this.statusAt(count);
    const status = {};
    codes.forEach((code, uid) => { if (code) status[uid] = STATUS_NAMES[code]; });
    const present = this.meta.nodes.filter((n) => n.added === null || n.added < count)
      .map((n) => n.uid);
    const board = new Map();
    const upto = upperBound(this.writeSeqs, count - 1);
    for (let w = 0; w < upto; w++) {
      const seq = this.writeSeqs[w];
      const [scope, key, value, type] = this.writes[this.st[seq]];
      const name = JSON.stringify([scope, key]);
      if (type === "unset") board.delete(name);
      else board.set(name, { scope, key, value, writer: this.uid[seq], seq });
    }
    const blackboard = [...board.values()].sort((a, b) =>
      a.scope < b.scope ? -1 : a.scope > b.scope ? 1 : a.key < b.key ? -1 : a.key > b.key ? 1 : 0);
    const set = this.answersAt(count);
    return {
      count, moment, t_ns: moment.t_ns, tick: moment.tick,
      status, present, current: set.current, blackboard, answers: set.answers,
      events: this.events(count),
    };
  }
  answersAt(count) {
    const index = upperBound(this.answers.at, count) - 1;
    const set = this.answers.sets[Math.max(0, index)];
    const table = this.answers.table;
    const answers = set.answers.map((i) =>
      table[i].nodes === undefined ? { ...table[i], nodes: set.current } : table[i]);
    return { current: set.current, answers };
  }
  events(count, before = 40) {
    const lo = Math.max(0, count - before), hi = Math.min(this.t.length, count + before);
    const rows = [];
    for (let i = lo; i < hi; i++) {
      const row = { seq: i, t_ns: this.t[i], tick: this.tick[i], uid: this.uid[i] };
      if (this.kind[i] === 0) {
        Object.assign(row, { kind: "status", prev: STATUS_NAMES[this.prev[i]],
          status: STATUS_NAMES[this.st[i]] });
      } else if (this.kind[i] === 1) {
        const [scope, key, value] = this.writes[this.st[i]];
        Object.assign(row, { kind: "write", scope, key, value });
      } else {
        row.kind = "mutation";
      }
      rows.push(row);
    }
    return { lo, rows };
  }
  gantt() {
    const execution = new Set(this.meta.nodes.filter((n) => n.kind === "action" ||
      n.kind === "condition").map((n) => n.uid));
    const open = new Map();
    const out = { uid: [], status: [], start: [], end: [] };
    const close = (uid, end) => {
      const seg = open.get(uid);
      if (seg && seg.status !== 0) {
        out.uid.push(uid); out.status.push(STATUS_NAMES[seg.status]);
        out.start.push(seg.t); out.end.push(end);
      }
    };
    for (let i = 0; i < this.t.length; i++) {
      if (this.kind[i] !== 0 || !execution.has(this.uid[i])) continue;
      close(this.uid[i], this.t[i]);
      open.set(this.uid[i], { t: this.t[i], status: this.st[i] });
    }
    for (const uid of open.keys()) close(uid, this.meta.duration_ns);
    return out;
  }
}

/** `12.5s`, `1500ms`, `-2s`… as integer nanoseconds, rounded as btlog rounds them. */
function exactTime(text) {
  const m = /^([+-]?)(\d+(?:\.\d*)?|\.\d+)\s*(s|ms|us|ns)?$/.exec(text);
  if (!m) return null;
  const scale = { s: 1e9, ms: 1e6, us: 1e3, ns: 1 }[m[3] || "s"];
  const [whole, fraction = ""] = m[2].split(".");
  let ns = Number(whole || "0") * scale;
  const digits = fraction.slice(0, 30);
  if (digits) {
    const denominator = 10 ** digits.length;
    ns += Math.floor((Number(digits) * scale + Math.floor(denominator / 2)) / denominator);
  }
  return m[1] === "-" ? -ns : ns;
}

class EmbeddedSource {
  /** An exported page: the data is in the page, every answer was computed by btlog. */
  async init() {
    const data = JSON.parse(document.getElementById("btlog-data").textContent);
    this.runs = data.runs.map((run) => new EmbeddedRun(run));
    this.info = { runs: this.runs.map((r) => r.meta), diff: data.diff, patterns: data.patterns,
      questions: data.questions, can_answer: data.can_answer, report: data.report,
      files: data.files };
    return this.info;
  }
  async state(run, request) {
    const r = this.runs[run];
    let moment;
    if (request.at !== undefined) moment = r.resolve(request.at);
    else if (request.t_ns !== undefined) {
      moment = r.resolve(timeMoment(Math.max(0, Math.min(r.meta.duration_ns, request.t_ns))));
    } else {
      const count = Math.max(0, Math.min(r.t.length, request.count));
      moment = r.resolve(`seq:${count - 1}`);
    }
    return r.state(moment);
  }
  async gantt(run, lo, hi) {
    if (this.segments === undefined) this.segments = this.runs.map(() => null);
    if (!this.segments[run]) this.segments[run] = this.runs[run].gantt();
    return this.segments[run];   // every interval, exact: the timeline clips to its window
  }
  async ask(run, moment, question) {
    const intent = questionIntent(this.info.patterns, question);
    if (intent === null) {
      return { question, intent: null,
        answer: `Sorry. I don't understand "${question.trim()}". I can answer: ${this.info.can_answer}` };
    }
    const found = this.runs[run].answersAt(moment.count).answers.find((a) => a.intent === intent);
    if (found) return { ...found, question };
    const at = moment.seq === null ? "tick:0" : `seq:${moment.seq}`;
    return { question, intent, offline: true, answer: "This exported page cannot answer that " +
      "offline: it holds the standard answers (" +
      this.info.questions.map(([, q]) => q).join(" ") + ") at every moment, and this question " +
      `needs the recording. Ask it there: btlog ask ${this.info.files[run]} --at ${at} ` +
      JSON.stringify(question.trim()) };
  }
}

/** The data source of this page: embedded data when present, else the server. */
function makeSource() {
  return document.getElementById("btlog-data") ? new EmbeddedSource() : new ServerSource();
}
