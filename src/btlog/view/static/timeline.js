// btlog view: the timeline under the tree - a time axis and one row per execution node
// with its non-IDLE intervals (a Gantt of the run: RUNNING bars, SUCCESS and FAILURE
// marks), and a cursor at the moment. Drag on it to scrub: onScrub(t_ns). The rows
// follow the current node (its row is scrolled into view and marked), and a node found
// by the search is scrolled to and marked as well.
"use strict";

const STATUS_COLOURS = { RUNNING: "#e0a100", SUCCESS: "#2e7d32", FAILURE: "#c62828",
  SKIPPED: "#00838f" };
const LABEL_W = 170, AXIS_H = 20, ROW_H = 16, ROW_PX = 11;

function niceStep(span) {
  const raw = span / 8, base = Math.pow(10, Math.floor(Math.log10(raw)));
  for (const m of [1, 2, 5, 10]) if (base * m >= raw) return base * m;
  return base * 10;
}

function formatSeconds(ns) {
  const s = ns / 1e9;
  return s >= 100 ? s.toFixed(0) + " s" : s >= 10 ? s.toFixed(1) + " s" : s.toFixed(2) + " s";
}

class Timeline {
  /** A Gantt of `nodes` (execution nodes, tree order) over `durationNs`. Only the rows
   * in view are drawn (the box scrolls over a spacer), so a 1,000-node tree costs what
   * a small one does. */
  constructor(box, nodes, durationNs, onScrub, onWindow, onRow) {
    this.box = box;
    this.rows = nodes.filter((n) => n.kind === "action" || n.kind === "condition");
    this.rowOf = new Map(this.rows.map((n, i) => [n.uid, i]));
    this.duration = Math.max(1, durationNs);
    this.onScrub = onScrub;
    this.onWindow = onWindow;
    this.onRow = onRow;
    this.lo = 0;
    this.hi = this.duration;
    this.view = document.createElement("div");
    this.view.className = "timelineview";
    box.appendChild(this.view);
    this.canvas = document.createElement("canvas");
    this.canvas.setAttribute("aria-label", "timeline");
    this.view.appendChild(this.canvas);
    this.cursorLine = document.createElement("div");
    this.cursorLine.className = "cursor";
    this.view.appendChild(this.cursorLine);
    this.spacer = document.createElement("div");
    box.appendChild(this.spacer);
    this.cursor = 0;
    this.segments = null;
    this.byRow = [];
    this.current = new Set();
    this.found = null;
    this.installScrub();
    box.addEventListener("scroll", () => this.draw(), { passive: true });
    new ResizeObserver(() => this.draw()).observe(box);
  }

  /** Intervals to draw; `lo`..`hi` is the window they were asked for (ignored when the
   * window has moved on since). */
  setSegments(segments, lo, hi) {
    if (lo !== undefined && (lo !== this.lo || hi !== this.hi)) return;
    this.segments = segments;
    this.byRow = this.rows.map(() => []);
    for (let i = 0; i < segments.uid.length; i++) {
      const row = this.rowOf.get(segments.uid[i]);
      if (row !== undefined) this.byRow[row].push(i);
    }
    this.draw();
  }

  setCursor(tNs) { this.cursor = tNs; this.drawCursor(); }

  /** Mark the current nodes' rows and scroll the first into view (when it is not). */
  follow(uids) {
    this.current = new Set(uids);
    const rows = uids.map((u) => this.rowOf.get(u)).filter((r) => r !== undefined);
    if (rows.length) this.scrollToRow(rows[0]);
    this.draw();
  }

  /** Mark a found node's row and scroll it into view. */
  showRow(uid) {
    this.found = uid;
    const row = this.rowOf.get(uid);
    if (row !== undefined) this.scrollToRow(row, true);
    this.draw();
  }

  scrollToRow(row, centre = false) {
    const top = this.box.scrollTop, height = this.box.clientHeight - AXIS_H;
    const y = row * ROW_H;
    if (centre || y < top || y + ROW_H > top + height) {
      this.box.scrollTop = Math.max(0, y - height / 2);
    }
  }

  plotWidth() { return this.box.clientWidth - LABEL_W - 10; }

  xOf(tNs) { return LABEL_W + ((tNs - this.lo) / (this.hi - this.lo)) * this.plotWidth(); }

  tOf(x) {
    const t = this.lo + ((x - LABEL_W) / this.plotWidth()) * (this.hi - this.lo);
    return Math.max(this.lo, Math.min(this.hi, t));
  }

  /** Zoom the time axis by `factor` around time `t` (wheel); the whole run at most. */
  zoom(factor, t) {
    const span = Math.min(this.duration, Math.max(1e6, (this.hi - this.lo) * factor));
    let lo = t - ((t - this.lo) / (this.hi - this.lo)) * span;
    lo = Math.max(0, Math.min(this.duration - span, lo));
    this.setWindow(lo, lo + span);
  }

  setWindow(lo, hi) {
    if (lo === this.lo && hi === this.hi) return;
    this.lo = lo; this.hi = hi;
    this.draw();
    clearTimeout(this.reload);
    const whole = lo <= 0 && hi >= this.duration;
    this.reload = setTimeout(() => this.onWindow(whole ? undefined : lo, whole ? undefined : hi),
      150);
  }

  draw() {
    const ratio = window.devicePixelRatio || 1;
    const width = this.box.clientWidth, height = this.box.clientHeight;
    if (!width || !height) return;
    const total = AXIS_H + this.rows.length * ROW_H + 4;
    this.spacer.style.height = `${Math.max(0, total - height)}px`;
    if (this.canvas.width !== width * ratio || this.canvas.height !== height * ratio) {
      this.canvas.width = width * ratio; this.canvas.height = height * ratio;
      this.canvas.style.width = width + "px"; this.canvas.style.height = height + "px";
    }
    const ctx = this.canvas.getContext("2d");
    ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
    ctx.fillStyle = "#fff"; ctx.fillRect(0, 0, width, height);
    ctx.font = `${ROW_PX}px system-ui, sans-serif`; ctx.textBaseline = "middle";
    const top = this.box.scrollTop;
    const first = Math.max(0, Math.floor(top / ROW_H));
    const last = Math.min(this.rows.length, Math.ceil((top + height - AXIS_H) / ROW_H) + 1);
    for (let row = first; row < last; row++) {
      const y = AXIS_H + row * ROW_H - top;
      const n = this.rows[row];
      if (this.current.has(n.uid) || this.found === n.uid) {
        ctx.fillStyle = this.found === n.uid ? "#fff3c4" : "#e3f2fd";
        ctx.fillRect(0, y, width, ROW_H);
      } else if (row % 2) { ctx.fillStyle = "#fafafa"; ctx.fillRect(0, y, width, ROW_H); }
      ctx.fillStyle = this.current.has(n.uid) ? "#1565c0" : "#444";
      ctx.fillText(fitText(n.name || n.type, ROW_PX, LABEL_W - 8), 4, y + ROW_H / 2);
      if (this.segments) this.drawRow(ctx, row, y);
    }
    ctx.fillStyle = "#fff"; ctx.fillRect(0, 0, width, AXIS_H);
    const step = niceStep(this.hi - this.lo);
    ctx.strokeStyle = "#e6e6e6"; ctx.fillStyle = "#666";
    for (let t = Math.ceil(this.lo / step) * step; t <= this.hi; t += step) {
      const x = Math.round(this.xOf(t)) + 0.5;
      ctx.beginPath(); ctx.moveTo(x, AXIS_H - 4); ctx.lineTo(x, height); ctx.stroke();
      ctx.fillText(formatSeconds(t), x + 2, 9);
    }
    this.drawCursor();
  }

  drawRow(ctx, row, y) {
    const s = this.segments;
    const right = LABEL_W + this.plotWidth();
    for (const i of this.byRow[row]) {
      if (s.end[i] < this.lo || s.start[i] > this.hi) continue;
      const status = s.status[i];
      const x0 = Math.max(LABEL_W, this.xOf(s.start[i])), x1 = Math.min(right, this.xOf(s.end[i]));
      ctx.fillStyle = STATUS_COLOURS[status] || "#999";
      if (status === "RUNNING") ctx.fillRect(x0, y + 2, Math.max(1, x1 - x0), ROW_H - 4);
      else if (status === "FAILURE") ctx.fillRect(x0 - 1, y + 1, 3, ROW_H - 2);
      else ctx.fillRect(x0, y + 1, Math.max(1, Math.min(2, x1 - x0)), ROW_H - 2);
    }
  }

  drawCursor() {
    const inside = this.cursor >= this.lo && this.cursor <= this.hi;
    if (!inside && !this.dragging) {   // follow the moment when it leaves the window
      const span = this.hi - this.lo;
      const lo = Math.max(0, Math.min(this.duration - span, this.cursor - span / 2));
      this.setWindow(lo, lo + span);
      return;
    }
    this.cursorLine.style.display = inside ? "" : "none";
    this.cursorLine.style.left = `${Math.round(this.xOf(this.cursor)) - 1}px`;
  }

  /** Drag to scrub; wheel to zoom the time axis (Shift+wheel or a sideways wheel pans);
   * a click on a row's label selects that node in the tree. */
  installScrub() {
    this.dragging = false;
    const at = (e) => {
      const r = this.canvas.getBoundingClientRect();
      return this.tOf(e.clientX - r.left);
    };
    this.canvas.addEventListener("pointerdown", (e) => {
      const r = this.canvas.getBoundingClientRect();
      if (e.clientX - r.left < LABEL_W) {
        const row = Math.floor((e.clientY - r.top - AXIS_H + this.box.scrollTop) / ROW_H);
        if (e.clientY - r.top > AXIS_H && this.rows[row]) this.onRow(this.rows[row].uid);
        return;
      }
      this.dragging = true;
      this.canvas.setPointerCapture(e.pointerId);
      this.onScrub(at(e));
    });
    this.canvas.addEventListener("pointermove", (e) => { if (this.dragging) this.onScrub(at(e)); });
    this.canvas.addEventListener("pointerup", () => { this.dragging = false; });
    this.canvas.addEventListener("wheel", (e) => {
      const sideways = e.shiftKey ? e.deltaY : e.deltaX;
      if (Math.abs(sideways) > Math.abs(e.shiftKey ? 0 : e.deltaY)) {
        e.preventDefault();
        const span = this.hi - this.lo;
        const lo = Math.max(0, Math.min(this.duration - span, this.lo + (sideways / 500) * span));
        this.setWindow(lo, lo + span);
      } else if (e.ctrlKey || e.altKey || !e.shiftKey) {
        if (e.clientX - this.canvas.getBoundingClientRect().left < LABEL_W) return; // scroll rows
        e.preventDefault();
        this.zoom(Math.exp(e.deltaY * 0.002), at(e));
      }
    }, { passive: false });
  }
}
