// btlog view: the tree drawn as a graph (SVG). Top-down boxes laid out as a tidy tree,
// coloured by status through the data-status attribute, the current node marked,
// subtrees collapsible, pan (drag) and zoom (wheel). Every recorded string is set with
// textContent, never parsed as markup.
"use strict";

const SVG_NS = "http://www.w3.org/2000/svg";
const BOX_W = 150, BOX_H = 40, GAP_X = 14, GAP_Y = 46;
/** Trees larger than this open with subtrees below OPEN_DEPTH collapsed (the path to the
 * current node is opened): readable at once, and far fewer elements to render. */
const LARGE_TREE = 300, OPEN_DEPTH = 2;

function svg(tag, attrs = {}, parent = null) {
  const el = document.createElementNS(SVG_NS, tag);
  for (const [k, v] of Object.entries(attrs)) el.setAttribute(k, v);
  if (parent) parent.appendChild(el);
  return el;
}

function clip(text, max) {
  return text.length > max ? text.slice(0, max - 1) + "\u2026" : text;
}

class TreeGraph {
  /** Draw `nodes` (the page's node records) into `box`; `onSelect(uid)` on a click. */
  constructor(box, nodes, rootUid, onSelect) {
    this.box = box;
    this.onSelect = onSelect;
    this.nodes = new Map(nodes.map((n) => [n.uid, { ...n, children: [] }]));
    for (const n of this.nodes.values()) {
      if (n.parent !== null && this.nodes.has(n.parent)) this.nodes.get(n.parent).children.push(n);
    }
    this.root = this.nodes.get(rootUid);
    this.collapsed = new Set();
    if (this.nodes.size > LARGE_TREE) this.collapseBelow(OPEN_DEPTH);
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
    this.installPanZoom();
    this.layout();
    this.fit();
  }

  makeNode(n) {
    const g = svg("g", { class: "node", "data-uid": n.uid,
      "data-status": this.state.status[n.uid] || "IDLE", "data-kind": n.kind }, this.nodeLayer);
    if (this.state.current.includes(n.uid)) g.classList.add("current");
    for (const cls of this.marks.get(n.uid) || []) g.classList.add(cls);
    if (this.selected === n.uid) g.classList.add("selected");
    const title = svg("title", {}, g);
    title.textContent = `${n.name || n.type} \u2014 ${n.type} (${n.kind}) #${n.uid}\n${n.path}`;
    svg("rect", { class: "box", width: BOX_W, height: BOX_H }, g);
    svg("rect", { class: "band", width: 5, height: BOX_H - 8, x: 3, y: 4 }, g);
    const name = svg("text", { class: "name", x: 13, y: 16 }, g);
    name.textContent = clip(n.name || n.type, 22);
    const type = svg("text", { class: "type", x: 13, y: 31 }, g);
    type.textContent = clip(`${n.type} \u00b7 ${n.kind}`, 26);
    const marker = svg("text", { class: "marker", x: BOX_W - 16, y: 16 }, g);
    marker.textContent = "\u25c9";
    if (n.children.length) {
      const toggle = svg("g", { class: "toggle", transform: `translate(${BOX_W / 2},${BOX_H})` }, g);
      svg("circle", { r: 7 }, toggle);
      n.toggleText = svg("text", { y: 4 }, toggle);
      n.toggleText.textContent = "\u2212";
      toggle.addEventListener("click", (e) => { e.stopPropagation(); this.toggle(n.uid); });
    }
    g.addEventListener("click", (e) => { e.stopPropagation(); this.select(n.uid); });
    this.elements.set(n.uid, g);
    if (n.parent !== null) this.edges.set(n.uid, svg("path", { class: "edge" }, this.edgeLayer));
  }

  /** Visible children: present at the moment and not under a collapsed node. */
  shown(n) {
    return this.collapsed.has(n.uid) ? [] : n.children.filter((c) => this.present.has(c.uid));
  }

  layout() {
    let slot = 0;
    const place = (n, depth) => {
      const kids = this.shown(n);
      n.y = depth * (BOX_H + GAP_Y);
      if (!kids.length) { n.x = slot * (BOX_W + GAP_X); slot += 1; }
      else {
        for (const c of kids) place(c, depth + 1);
        n.x = (kids[0].x + kids[kids.length - 1].x) / 2;
      }
      n.visible = true;
    };
    for (const n of this.nodes.values()) n.visible = false;
    place(this.root, 0);
    for (const n of this.nodes.values()) {
      if (n.visible && !this.elements.has(n.uid)) this.makeNode(n);
      const g = this.elements.get(n.uid);
      if (!g) continue;
      g.classList.toggle("absent", !n.visible);
      if (n.visible) g.setAttribute("transform", `translate(${n.x},${n.y})`);
      if (n.toggleText) n.toggleText.textContent = this.collapsed.has(n.uid) ? "+" : "\u2212";
      const edge = this.edges.get(n.uid);
      if (!edge) continue;
      const p = this.nodes.get(n.parent);
      edge.style.display = n.visible ? "" : "none";
      if (n.visible) {
        const x1 = p.x + BOX_W / 2, y1 = p.y + BOX_H + 7, x2 = n.x + BOX_W / 2, y2 = n.y;
        const my = (y1 + y2) / 2;
        edge.setAttribute("d", `M${x1},${y1} C${x1},${my} ${x2},${my} ${x2},${y2}`);
      }
    }
    this.width = slot * (BOX_W + GAP_X);
  }

  collapseBelow(depth) {
    const walk = (n, d) => {
      if (d >= depth && n.children.length) this.collapsed.add(n.uid);
      for (const c of n.children) walk(c, d + 1);
    };
    walk(this.root, 0);
  }

  expandAll() {
    this.collapsed.clear();
    this.layout();
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
    if (changed) this.layout();
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

  /** Expand every ancestor of `uid` and bring it into view. */
  /** Readable at once: the whole tree when it fits at a legible size, else zoomed on `uid`. */
  home(uid) {
    if (uid !== undefined) this.open(uid);
    this.fit();
    if (this.zoom.k >= 0.6) return;
    const target = this.nodes.get(uid === undefined ? this.root.uid : uid);
    if (!target || !target.visible) { this.zoom.k = 0.8; this.apply(); return; }
    const w = this.box.clientWidth, h = this.box.clientHeight, k = 0.8;
    this.zoom = { k, x: w / 2 - (target.x + BOX_W / 2) * k, y: Math.min(20, h / 2 - target.y * k) };
    this.apply();
  }

  /** Expand every ancestor of `uid`. */
  open(uid) {
    let n = this.nodes.get(uid);
    let changed = false;
    while (n && n.parent !== null) {
      n = this.nodes.get(n.parent);
      if (n && this.collapsed.delete(n.uid)) changed = true;
    }
    if (changed) this.layout();
  }

  reveal(uid) {
    this.open(uid);
    this.follow(uid);
  }

  /** Pan to `uid` when it is drawn but outside the view (subtrees stay as they are). */
  follow(uid) {
    const target = this.nodes.get(uid);
    const w = this.box.clientWidth, h = this.box.clientHeight, k = this.zoom.k;
    if (!target || !target.visible || !w || !h) return;
    const sx = target.x * k + this.zoom.x, sy = target.y * k + this.zoom.y;
    if (sx < 0 || sy < 0 || sx + BOX_W * k > w || sy + BOX_H * k > h) {
      this.zoom.x = w / 2 - (target.x + BOX_W / 2) * k;
      this.zoom.y = h / 2 - (target.y + BOX_H / 2) * k;
      this.apply();
    }
  }

  apply() {
    const { x, y, k } = this.zoom;
    this.view.setAttribute("transform", `translate(${x},${y}) scale(${k})`);
  }

  fit() {
    const w = this.box.clientWidth || 800, h = this.box.clientHeight || 500;
    let depth = 0;
    for (const n of this.nodes.values()) if (n.visible) depth = Math.max(depth, n.y);
    const height = depth + BOX_H + 20;
    const k = Math.max(0.15, Math.min(1.2, (w - 40) / Math.max(1, this.width), (h - 40) / height));
    this.zoom = { k, x: (w - this.width * k) / 2, y: 20 };
    this.apply();
  }

  zoomBy(factor, cx, cy) {
    const z = this.zoom;
    const k = Math.max(0.05, Math.min(4, z.k * factor));
    z.x = cx - ((cx - z.x) * k) / z.k;
    z.y = cy - ((cy - z.y) * k) / z.k;
    z.k = k;
    this.apply();
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
}
