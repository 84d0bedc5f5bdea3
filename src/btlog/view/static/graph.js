// btlog view: the tree drawn as a graph (SVG). Top-down boxes, each as wide as its
// label (up to a cap), laid out as a tidy tree; coloured by status through the
// data-status attribute, the current node marked, subtrees collapsible, pan (drag) and
// zoom (wheel), an overview (minimap) when the tree is larger than the view, full
// labels on hover. "fit" shows the whole tree with its labels at least MIN_LABEL_PX
// tall, collapsing the deepest levels until it does (the path to the current node stays
// open). Every recorded string is set with textContent, never parsed as markup.
"use strict";

const SVG_NS = "http://www.w3.org/2000/svg";
const NAME_PX = 13, TYPE_PX = 12, MIN_LABEL_PX = 11;
const BOX_H = 40, MIN_W = 80, MAX_W = 190, PAD_X = 20, GAP_X = 10, GAP_Y = 30;
/** The smallest zoom at which the smallest label is MIN_LABEL_PX tall, and the largest. */
const MIN_K = MIN_LABEL_PX / TYPE_PX, MAX_FIT_K = 1.3;

function svg(tag, attrs = {}, parent = null) {
  const el = document.createElementNS(SVG_NS, tag);
  for (const [k, v] of Object.entries(attrs)) el.setAttribute(k, v);
  if (parent) parent.appendChild(el);
  return el;
}

/** Text measured in the page's font (a canvas), and clipped to a width with "…". */
const measure = (() => {
  const ctx = document.createElement("canvas").getContext("2d");
  return (text, px, weight = 400) => {
    ctx.font = `${weight} ${px}px system-ui, -apple-system, "Segoe UI", sans-serif`;
    return ctx.measureText(text).width;
  };
})();

function fitText(text, px, width, weight) {
  if (measure(text, px, weight) <= width) return text;
  let lo = 0, hi = text.length;
  while (lo < hi) {
    const mid = (lo + hi + 1) >> 1;
    if (measure(text.slice(0, mid) + "\u2026", px, weight) <= width) lo = mid; else hi = mid - 1;
  }
  return text.slice(0, lo) + "\u2026";
}

function clip(text, max) {
  return text.length > max ? text.slice(0, max - 1) + "\u2026" : text;
}

class TreeGraph {
  /** Draw `nodes` (the page's node records) into `box`; `onSelect(uid)` on a click. */
  constructor(box, nodes, rootUid, onSelect) {
    this.box = box;
    this.onSelect = onSelect;
    this.nodes = new Map(nodes.map((n) => [n.uid, { ...n, children: [], depth: 0 }]));
    for (const n of this.nodes.values()) {
      if (n.parent !== null && this.nodes.has(n.parent)) this.nodes.get(n.parent).children.push(n);
    }
    this.root = this.nodes.get(rootUid);
    const deep = (n, d) => { n.depth = d; n.children.forEach((c) => deep(c, d + 1)); };
    deep(this.root, 0);
    for (const n of this.nodes.values()) {
      n.label = n.name || n.type;
      n.typeLabel = `${n.type} \u00b7 ${n.kind}`;
      const want = Math.max(measure(n.label, NAME_PX, 600), measure(n.typeLabel, TYPE_PX));
      n.w = Math.round(Math.max(MIN_W, Math.min(MAX_W, want + PAD_X)));
    }
    this.collapsed = new Set();
    this.present = new Set(this.nodes.keys());
    this.selected = null;
    this.svg = svg("svg", { "aria-label": "behavior tree" }, box);
    this.view = svg("g", { class: "viewport" }, this.svg);
    this.edgeLayer = svg("g", {}, this.view);
    this.nodeLayer = svg("g", {}, this.view);
    // Elements are made when a node is first shown (a collapsed subtree costs nothing).
    this.elements = new Map();
    this.edges = new Map();
    this.marks = new Map();
    this.state = { status: {}, current: [] };
    this.zoom = { x: 20, y: 20, k: 1 };
    this.tip = el("div", { class: "tip", role: "tooltip" }, box);
    this.minimap = el("canvas", { class: "minimap", "aria-label": "overview" }, box);
    this.installPanZoom();
    this.installMinimap();
    this.layout();
    new ResizeObserver(() => this.drawMinimap()).observe(box);
  }

  makeNode(n) {
    const g = svg("g", { class: "node", "data-uid": n.uid,
      "data-status": this.state.status[n.uid] || "IDLE", "data-kind": n.kind }, this.nodeLayer);
    if (this.state.current.includes(n.uid)) g.classList.add("current");
    for (const cls of this.marks.get(n.uid) || []) g.classList.add(cls);
    if (this.selected === n.uid) g.classList.add("selected");
    svg("rect", { class: "box", width: n.w, height: BOX_H }, g);
    svg("rect", { class: "band", width: 5, height: BOX_H - 8, x: 3, y: 4 }, g);
    const name = svg("text", { class: "name", x: 13, y: 17 }, g);
    name.textContent = fitText(n.label, NAME_PX, n.w - PAD_X + 4, 600);
    const type = svg("text", { class: "type", x: 13, y: 32 }, g);
    type.textContent = fitText(n.typeLabel, TYPE_PX, n.w - PAD_X + 4);
    const marker = svg("text", { class: "marker", x: n.w - 15, y: 16 }, g);
    marker.textContent = "\u25c9";
    if (n.children.length) {
      const toggle = svg("g", { class: "toggle", transform: `translate(${n.w / 2},${BOX_H})` }, g);
      svg("circle", { r: 8 }, toggle);
      n.toggleText = svg("text", { y: 4 }, toggle);
      n.hidden = svg("text", { class: "hidden-count", x: 12, y: 4 }, toggle);
      toggle.addEventListener("click", (e) => { e.stopPropagation(); this.toggle(n.uid); });
    }
    g.addEventListener("click", (e) => { e.stopPropagation(); this.select(n.uid); });
    g.addEventListener("pointerenter", (e) => this.showTip(n, e));
    g.addEventListener("pointermove", (e) => this.moveTip(e));
    g.addEventListener("pointerleave", () => { this.tip.style.display = "none"; });
    this.elements.set(n.uid, g);
    if (n.parent !== null) this.edges.set(n.uid, svg("path", { class: "edge" }, this.edgeLayer));
  }

  /** The full label of a node, on hover (boxes clip long names). */
  showTip(n, e) {
    this.tip.replaceChildren();
    el("div", { class: "tipname" }, this.tip, n.label);
    el("div", {}, this.tip, `${n.type} \u00b7 ${n.kind} \u00b7 #${n.uid} \u00b7 ` +
      (this.state.status[n.uid] || "IDLE"));
    if (n.path) el("div", { class: "muted" }, this.tip, n.path);
    this.tip.style.display = "block";
    this.moveTip(e);
  }

  moveTip(e) {
    const r = this.box.getBoundingClientRect();
    const x = Math.min(e.clientX - r.left + 14, r.width - this.tip.offsetWidth - 4);
    this.tip.style.left = `${Math.max(4, x)}px`;
    this.tip.style.top = `${e.clientY - r.top + 16}px`;
  }

  /** Visible children: present at the moment and not under a collapsed node. */
  shown(n) {
    return this.collapsed.has(n.uid) ? [] : n.children.filter((c) => this.present.has(c.uid));
  }

  /** A tidy layout: leaves side by side, a parent centred over its children, a subtree
   * moved right when it would overlap what is already placed at one of its depths. */
  layout() {
    const right = [];   // the right edge placed so far at each depth
    let cursor = 0;
    const shift = (n, dx, depth) => {
      n.x += dx;
      right[depth] = Math.max(right[depth] ?? -Infinity, n.x + n.w);
      for (const c of this.shown(n)) shift(c, dx, depth + 1);
    };
    const place = (n, depth) => {
      const kids = this.shown(n);
      n.y = depth * (BOX_H + GAP_Y);
      n.visible = true;
      if (!kids.length) {
        n.x = Math.max(cursor, (right[depth] ?? -Infinity) + GAP_X);
      } else {
        for (const c of kids) place(c, depth + 1);
        const first = kids[0], last = kids[kids.length - 1];
        n.x = (first.x + first.w / 2 + last.x + last.w / 2) / 2 - n.w / 2;
        const clash = (right[depth] ?? -Infinity) + GAP_X - n.x;
        if (clash > 0) shift(n, clash, depth);
      }
      right[depth] = n.x + n.w;
      cursor = Math.max(cursor, n.x + n.w + GAP_X);
    };
    for (const n of this.nodes.values()) n.visible = false;
    place(this.root, 0);
    let minX = Infinity, maxX = -Infinity, maxY = 0;
    for (const n of this.nodes.values()) {
      if (n.visible) {
        minX = Math.min(minX, n.x); maxX = Math.max(maxX, n.x + n.w); maxY = Math.max(maxY, n.y);
      }
    }
    this.bounds = { x: minX, width: maxX - minX, height: maxY + BOX_H + 10 };
    for (const n of this.nodes.values()) {
      if (n.visible && !this.elements.has(n.uid)) this.makeNode(n);
      const g = this.elements.get(n.uid);
      if (!g) continue;
      g.classList.toggle("absent", !n.visible);
      if (n.visible) g.setAttribute("transform", `translate(${n.x},${n.y})`);
      if (n.toggleText) {
        const closed = this.collapsed.has(n.uid);
        n.toggleText.textContent = closed ? "+" : "\u2212";
        n.hidden.textContent = closed ? String(this.descendants(n)) : "";
        g.classList.toggle("collapsed", closed);
      }
      const edge = this.edges.get(n.uid);
      if (!edge) continue;
      const p = this.nodes.get(n.parent);
      edge.style.display = n.visible ? "" : "none";
      if (n.visible) {
        const x1 = p.x + p.w / 2, y1 = p.y + BOX_H + 8, x2 = n.x + n.w / 2, y2 = n.y;
        const my = (y1 + y2) / 2;
        edge.setAttribute("d", `M${x1},${y1} C${x1},${my} ${x2},${my} ${x2},${y2}`);
      }
    }
    this.markHolders();
    this.drawMinimap();
  }

  descendants(n) {
    let count = 0;
    const walk = (m) => { for (const c of m.children) { count += 1; walk(c); } };
    walk(n);
    return count;
  }

  /** The drawn node that shows `uid`: itself, or its collapsed ancestor. */
  holder(uid) {
    let n = this.nodes.get(uid);
    while (n && !n.visible) n = this.nodes.get(n.parent);
    return n;
  }

  /** Ring the collapsed node that hides a current node. */
  markHolders() {
    const holders = new Set(this.state.current.map((u) => this.holder(u)?.uid));
    for (const [uid, g] of this.elements) {
      const holds = holders.has(uid) && !this.state.current.includes(uid);
      if (g.classList.contains("holds-current") !== holds) g.classList.toggle("holds-current", holds);
    }
  }

  collapseBelow(depth, keepOpen = []) {
    this.collapsed.clear();
    for (const n of this.nodes.values()) {
      if (n.depth >= depth && n.children.length) this.collapsed.add(n.uid);
    }
    for (const uid of keepOpen) this.openPath(uid);
  }

  expandAll() {
    this.collapsed.clear();
    this.layout();
    this.fitView();
  }

  toggle(uid) {
    if (this.collapsed.has(uid)) this.collapsed.delete(uid); else this.collapsed.add(uid);
    this.layout();
  }

  /** Show one moment: statuses, nodes present, the current node(s). */
  update(state) {
    const present = new Set(state.present);
    let changed = present.size !== this.present.size;
    if (!changed) for (const uid of present) if (!this.present.has(uid)) { changed = true; break; }
    this.present = present;
    const current = new Set(state.current);
    this.state = state;
    for (const [uid, g] of this.elements) {
      const status = state.status[uid] || "IDLE";
      if (g.getAttribute("data-status") !== status) g.setAttribute("data-status", status);
      const isCurrent = current.has(uid);
      if (g.classList.contains("current") !== isCurrent) g.classList.toggle("current", isCurrent);
    }
    if (changed) this.layout(); else { this.markHolders(); this.drawMinimap(); }
  }

  select(uid) {
    if (this.selected !== null) this.elements.get(this.selected)?.classList.remove("selected");
    this.selected = uid;
    if (uid !== null) this.elements.get(uid)?.classList.add("selected");
    this.onSelect(uid);
  }

  mark(uids, cls) {
    for (const uid of uids) {
      if (!this.marks.has(uid)) this.marks.set(uid, new Set());
      this.marks.get(uid).add(cls);
      this.elements.get(uid)?.classList.add(cls);
    }
  }

  /** Fit: the whole tree readable, collapsing the deepest levels until its labels are
   * at least MIN_LABEL_PX at the zoom that shows it all — with the current nodes' paths
   * open if that can fit, else with them collapsed too (the collapsed node holding a
   * current node is ringed); when even the top is too wide, the readable zoom centred
   * on the current node. */
  fit(keepOpen = this.state.current) {
    const w = this.box.clientWidth || 800, h = this.box.clientHeight || 500;
    let depth = 0;
    for (const n of this.nodes.values()) depth = Math.max(depth, n.depth);
    for (const open of keepOpen.length ? [keepOpen, []] : [[]]) {
      for (let d = depth; d >= 1; d--) {
        this.collapseBelow(d, open);
        this.layout();
        if (this.fitScale(w, h) >= MIN_K) { this.fitView(keepOpen[0]); return; }
      }
    }
    this.fitView(keepOpen[0]);
  }

  fitScale(w, h) {
    return Math.min(MAX_FIT_K, (w - 40) / Math.max(1, this.bounds.width),
      (h - 50) / Math.max(1, this.bounds.height));
  }

  /** Zoom to show the laid-out tree, never below the readable zoom. */
  fitView(focus) {
    const w = this.box.clientWidth || 800, h = this.box.clientHeight || 500;
    const k = Math.max(MIN_K, this.fitScale(w, h));
    const width = this.bounds.width * k, height = this.bounds.height * k;
    this.zoom = { k, x: (w - width) / 2 - this.bounds.x * k, y: Math.max(16, (h - height) / 2) };
    const target = focus === undefined ? null : this.holder(focus);
    if (width > w - 20 && target) this.zoom.x = w / 2 - (target.x + target.w / 2) * k;
    if (height > h - 20 && target) this.zoom.y = Math.min(16, h / 2 - target.y * k);
    this.apply();
  }

  /** Readable at once: fit, around the current node. */
  home(uid) {
    this.fit(uid === undefined ? this.state.current : [uid]);
  }

  /** Open every ancestor of `uid` (no layout). */
  openPath(uid) {
    let n = this.nodes.get(uid);
    let changed = false;
    while (n && n.parent !== null) {
      n = this.nodes.get(n.parent);
      if (n && this.collapsed.delete(n.uid)) changed = true;
    }
    return changed;
  }

  /** Expand every ancestor of `uid`. */
  open(uid) {
    if (this.openPath(uid)) this.layout();
  }

  reveal(uid) {
    this.open(uid);
    this.follow(uid, true);
  }

  /** Pan to `uid` (or the collapsed node holding it) when it is outside the view; with
   * `centre`, always centre it. */
  follow(uid, centre = false) {
    const target = this.holder(uid);
    const w = this.box.clientWidth, h = this.box.clientHeight, k = this.zoom.k;
    if (!target || !w || !h) return;
    const sx = target.x * k + this.zoom.x, sy = target.y * k + this.zoom.y;
    if (centre || sx < 0 || sy < 0 || sx + target.w * k > w || sy + BOX_H * k > h) {
      this.zoom.x = w / 2 - (target.x + target.w / 2) * k;
      this.zoom.y = h / 2 - (target.y + BOX_H / 2) * k;
      this.apply();
    }
  }

  apply() {
    const { x, y, k } = this.zoom;
    this.view.setAttribute("transform", `translate(${x},${y}) scale(${k})`);
    this.drawMinimap();
  }

  zoomBy(factor, cx, cy) {
    const z = this.zoom;
    const k = Math.max(0.05, Math.min(4, z.k * factor));
    z.x = cx - ((cx - z.x) * k) / z.k;
    z.y = cy - ((cy - z.y) * k) / z.k;
    z.k = k;
    this.apply();
  }

  /** The overview: every drawn node as a dot in its status colour, and the view's
   * rectangle; shown only when the tree is larger than the view. */
  drawMinimap() {
    const map = this.minimap, w = this.box.clientWidth, h = this.box.clientHeight;
    if (!this.bounds || !w) return;
    const { k } = this.zoom;
    const inside = this.bounds.width * k <= w && this.bounds.height * k <= h &&
      this.bounds.x * k + this.zoom.x >= 0 && this.zoom.y >= 0 &&
      (this.bounds.x + this.bounds.width) * k + this.zoom.x <= w && this.bounds.height * k + this.zoom.y <= h;
    map.style.display = inside ? "none" : "block";
    if (inside) return;
    const mw = 180, mh = Math.max(50, Math.min(120, (mw * this.bounds.height) / this.bounds.width));
    const ratio = window.devicePixelRatio || 1;
    map.width = mw * ratio; map.height = mh * ratio;
    map.style.width = `${mw}px`; map.style.height = `${mh}px`;
    const s = Math.min((mw - 8) / this.bounds.width, (mh - 8) / this.bounds.height);
    this.mapScale = { s, ox: 4 - this.bounds.x * s, oy: 4 };
    const ctx = map.getContext("2d");
    ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
    ctx.fillStyle = "rgba(255,255,255,.92)"; ctx.fillRect(0, 0, mw, mh);
    const colours = { IDLE: "#bdbdbd", RUNNING: "#e0a100", SUCCESS: "#2e7d32", FAILURE: "#c62828",
      SKIPPED: "#00838f" };
    for (const n of this.nodes.values()) {
      if (!n.visible) continue;
      ctx.fillStyle = this.state.current.includes(n.uid) ? "#1565c0"
        : colours[this.state.status[n.uid] || "IDLE"];
      ctx.fillRect(this.mapScale.ox + n.x * s, this.mapScale.oy + n.y * s,
        Math.max(2, n.w * s), Math.max(2, BOX_H * s));
    }
    ctx.strokeStyle = "#1565c0"; ctx.lineWidth = 1.5;
    ctx.strokeRect(this.mapScale.ox + (-this.zoom.x / k) * s, this.mapScale.oy + (-this.zoom.y / k) * s,
      (w / k) * s, (h / k) * s);
  }

  installMinimap() {
    const jump = (e) => {
      if (!this.mapScale) return;
      const r = this.minimap.getBoundingClientRect();
      const { s, ox, oy } = this.mapScale, k = this.zoom.k;
      const tx = (e.clientX - r.left - ox) / s, ty = (e.clientY - r.top - oy) / s;
      this.zoom.x = this.box.clientWidth / 2 - tx * k;
      this.zoom.y = this.box.clientHeight / 2 - ty * k;
      this.apply();
    };
    let dragging = false;
    this.minimap.addEventListener("pointerdown", (e) => {
      e.stopPropagation(); dragging = true; this.minimap.setPointerCapture(e.pointerId); jump(e);
    });
    this.minimap.addEventListener("pointermove", (e) => { if (dragging) jump(e); });
    this.minimap.addEventListener("pointerup", () => { dragging = false; });
  }

  installPanZoom() {
    this.svg.addEventListener("wheel", (e) => {
      e.preventDefault();
      const r = this.svg.getBoundingClientRect();
      this.zoomBy(Math.exp(-e.deltaY * 0.0015), e.clientX - r.left, e.clientY - r.top);
    }, { passive: false });
    let drag = null;
    this.svg.addEventListener("pointerdown", (e) => {
      drag = { x: e.clientX, y: e.clientY, zx: this.zoom.x, zy: this.zoom.y, moved: false };
    });
    window.addEventListener("pointermove", (e) => {
      if (!drag) return;
      const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
      if (!drag.moved && Math.abs(dx) + Math.abs(dy) < 3) return;
      drag.moved = true;
      this.svg.classList.add("panning");
      this.zoom.x = drag.zx + dx; this.zoom.y = drag.zy + dy;
      this.apply();
    });
    window.addEventListener("pointerup", () => {
      drag = null; this.svg.classList.remove("panning");
    });
  }

  /** Nodes whose name, type or path holds `text` (case-insensitive), in tree order. */
  find(text) {
    const q = text.trim().toLowerCase();
    if (!q) return [];
    const found = [];
    const walk = (n) => {
      if ([n.name, n.type, n.path].some((s) => (s || "").toLowerCase().includes(q))) found.push(n.uid);
      n.children.forEach(walk);
    };
    walk(this.root);
    return found;
  }
}
