// btlog view: where the data comes from.
// ServerSource asks `btlog view`'s server (the read model); EmbeddedSource folds the
// events of an exported page in the browser. Both answer the same calls with the same
// shapes, so the rest of the page does not know which one it has.
"use strict";

const STATUS_NAMES = ["IDLE", "RUNNING", "SUCCESS", "FAILURE", "SKIPPED"];

/** Parse a deep-link value such as "12.5s", "1500ms" or "12.5" into nanoseconds. */
function parseTime(text) {
  const m = /^\s*(-?[0-9]*\.?[0-9]+)\s*(s|ms|us|ns)?\s*$/.exec(text);
  if (!m) return null;
  const scale = { s: 1e9, ms: 1e6, us: 1e3, ns: 1 }[m[2] || "s"];
  return Math.round(parseFloat(m[1]) * scale);
}

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
  state(run, count) { return this.get(`/api/run/${run}/state?count=${count}`); }
  stateAtTime(run, tNs) { return this.get(`/api/run/${run}/state?t_ns=${Math.round(tNs)}`); }
  gantt(run, lo, hi) {
    const window = lo === undefined ? "" : `?lo=${Math.floor(lo)}&hi=${Math.ceil(hi)}`;
    return this.get(`/api/run/${run}/gantt${window}`);
  }
  async step(run, count, dir) {
    return (await this.get(`/api/run/${run}/step?count=${count}&dir=${dir}`)).count;
  }
  async resolve(run, kind, value) {
    const at = encodeURIComponent(momentText(kind, value));
    return (await this.get(`/api/run/${run}/resolve?at=${at}`)).count;
  }
  stateAt(run, kind, value) {
    return this.get(`/api/run/${run}/state?at=${encodeURIComponent(momentText(kind, value))}`);
  }
  ask(run, count, question) {
    return this.get(`/api/run/${run}/ask?count=${count}&q=${encodeURIComponent(question)}`);
  }
}

class EmbeddedRun {
  /** One exported run: its events as columns, folded here on demand. */
  constructor(data) {
    this.meta = data.meta;
    const ev = data.events;
    this.t = ev.t; this.tick = ev.tick; this.kind = ev.kind; this.uid = ev.uid;
    this.st = ev.st; this.prev = ev.prev; this.writes = ev.writes;
    this.answers = data.answers;          // {at: [count...], sets: [[answer...]...]}
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
  state(count) {
    count = Math.max(0, Math.min(this.t.length, count));
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
      count, t_ns: count ? this.t[count - 1] : 0, tick: count ? this.tick[count - 1] : 0,
      status, present, current: set.current, blackboard, answers: set.answers,
      events: this.events(count),
    };
  }
  answersAt(count) {
    const index = upperBound(this.answers.at, count) - 1;
    return this.answers.sets[Math.max(0, index)];
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
  step(count, dir) {
    const n = this.t.length;
    if (dir > 0) return count >= n ? n : upperBound(this.tick, this.tick[count]);
    return count <= 0 ? 0 : upperBound(this.tick, this.tick[count - 1] - 1);
  }
}

class EmbeddedSource {
  /** An exported page: the data is in the page, every answer was computed by btlog. */
  async init() {
    const data = JSON.parse(document.getElementById("btlog-data").textContent);
    this.runs = data.runs.map((run) => new EmbeddedRun(run));
    this.info = { runs: this.runs.map((r) => r.meta), diff: data.diff, patterns: data.patterns,
      questions: data.questions, can_answer: data.can_answer, report: data.report };
    return this.info;
  }
  async state(run, count) { return this.runs[run].state(count); }
  async stateAtTime(run, tNs) {
    return this.runs[run].state(upperBound(this.runs[run].t, tNs));
  }
  async gantt(run, lo, hi) {
    if (this.segments === undefined) this.segments = this.runs.map(() => null);
    if (!this.segments[run]) this.segments[run] = this.runs[run].gantt();
    return this.segments[run];   // every interval, exact: the timeline clips to its window
  }
  async step(run, count, dir) { return this.runs[run].step(count, dir); }
  async resolve(run, kind, value) {
    const r = this.runs[run];
    if (kind === "seq") return Math.max(0, Math.min(r.t.length, Number(value) + 1));
    if (kind === "tick") return upperBound(r.tick, Number(value));
    const t = parseTime(value);
    if (t === null) throw new Error(`not a time: ${value}`);
    return t < 0 ? upperBound(r.t, r.meta.duration_ns + t) : upperBound(r.t, t);
  }
  async stateAt(run, kind, value) {
    return this.runs[run].state(await this.resolve(run, kind, value));
  }
  async ask(run, count, question) {
    const intent = questionIntent(this.info.patterns, question);
    if (intent === null) {
      return { question, intent: null,
        answer: `Sorry. I don't understand "${question.trim()}". I can answer: ${this.info.can_answer}` };
    }
    if (intent === "can") {
      return { question, intent, answer: "\"Can you X?\" is answered by `btlog view` on the recording " +
        "(this exported page holds the standard answers only)." };
    }
    const found = this.runs[run].answersAt(count).answers.find((a) => a.intent === intent);
    return { ...found, question };
  }
}

/** The data source of this page: embedded data when present, else the server. */
function makeSource() {
  return document.getElementById("btlog-data") ? new EmbeddedSource() : new ServerSource();
}
