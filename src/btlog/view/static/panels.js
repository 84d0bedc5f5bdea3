// btlog view: the side panels of a pane - the run's story (its failure episodes and
// subgoals, each a link to its moment), the selected node (ports and their blackboard
// values), the answers at the moment and the ask box, the event list around the moment,
// and the blackboard with each entry's writer. Text only (textContent) for recorded data.
// The story is btlog explain's JSON as it is, rendered generically: episodes with a time,
// a sentence, the handling and a count; subgoals with a result and times.
"use strict";

function el(tag, attrs = {}, parent = null, text = null) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
  if (text !== null) e.textContent = text;
  if (parent) parent.appendChild(e);
  return e;
}

function showValue(value) {
  return typeof value === "string" ? JSON.stringify(value) : JSON.stringify(value);
}

function seconds(ns) { return (ns / 1e9).toFixed(3) + " s"; }

class SidePanels {
  /** The panels of one pane; `pane` gives nodes, the moment and the ask call. */
  constructor(box, pane) {
    this.pane = pane;
    this.storyBox = el("section", { class: "story" }, box);
    this.showStory(pane.meta.story);
    this.nodeBox = el("section", { class: "selection" }, box);
    el("h2", {}, this.nodeBox, "Node");
    this.nodeBody = el("div", { class: "muted" }, this.nodeBox, "Click a node to see its ports.");
    const answers = el("section", { class: "answers" }, box);
    el("h2", {}, answers, "Answers at this moment");
    this.answerList = el("dl", {}, answers);
    const form = el("form", { class: "ask" }, answers);
    this.askInput = el("input", { type: "text", name: "q", placeholder: "Ask: What went wrong?",
      "aria-label": "question" }, form);
    el("button", { type: "submit" }, form, "Ask");
    this.askAnswer = el("div", { class: "askanswer", "aria-live": "polite" }, answers);
    form.addEventListener("submit", (e) => {
      e.preventDefault();
      this.pane.ask(this.askInput.value);
    });
    this.askInput.addEventListener("keydown", (e) => e.stopPropagation());
    const events = el("section", {}, box);
    el("h2", {}, events, "Events");
    this.eventList = el("div", { class: "events" }, events);
    const board = el("section", {}, box);
    el("h2", {}, board, "Blackboard");
    this.board = el("table", { class: "kv blackboard" }, board);
  }

  name(uid) {
    if (uid === null || uid === undefined) return "";
    const n = this.pane.nodes.get(uid);
    return n ? `${n.name || n.type} #${uid}` : `#${uid}`;
  }

  /** The run's story: a header, its failure episodes and subgoals as links. */
  showStory(story) {
    const box = this.storyBox;
    box.replaceChildren();
    el("h2", {}, box, "The run's story");
    if (!story) { el("div", { class: "muted" }, box, "(no story)"); return; }
    const seconds = (ns) => (ns / 1e9).toFixed(3) + " s";
    const outcome = [story.goal && `Goal: ${story.goal}.`, story.outcome && `Outcome: ${story.outcome}` +
      (story.duration_ns !== undefined ? ` after ${seconds(story.duration_ns)}` : "") + "."]
      .filter(Boolean).join(" ");
    el("div", { class: "storyhead" }, box, outcome);
    if (story.why) el("div", {}, box, story.why);
    const gaps = story.gaps || [];
    if (gaps.length) el("div", { class: "muted" }, box, `Gaps in the data: ${gaps.length}`);
    const gapList = el("ul", { class: "gaps" }, box);
    for (const gap of gaps) {
      const item = el("li", {}, gapList);
      const link = el("a", { href: "#", class: "moment-link", "data-t-ns": gap.from_ns }, item,
        `No data from ${seconds(gap.from_ns)} to ${seconds(gap.to_ns)}`);
      link.addEventListener("click", (e) => { e.preventDefault(); this.pane.go({ t_ns: gap.from_ns }); });
      el("div", { class: "muted" }, item, gap.why);
    }
    const runs = story.goal_runs || [];
    const runCount = story.goal_run_count ?? runs.length;  // the first runs and the last are listed
    if (runCount > 1) {  // a goal run again and again (a tree ticked in a loop)
      el("div", { class: "muted" }, box, `The goal ran ${runCount} times:`);
      const runList = el("ol", { class: "runs" }, box);
      for (const [index, run] of runs.entries()) {
        const last = index === runs.length - 1 && runCount > runs.length;
        const item = el("li", last ? { value: runCount } : {}, runList);
        const link = el("a", { href: "#", class: "moment-link", "data-t-ns": run.start_ns }, item,
          run.end_ns === null || run.end_ns === undefined ? `running since ${seconds(run.start_ns)}`
            : `${run.result || "halted"} in ${seconds(run.end_ns - run.start_ns)}`);
        link.addEventListener("click", (e) => { e.preventDefault(); this.pane.go({ t_ns: run.start_ns }); });
      }
    }
    const episodes = story.episodes || [];
    const told = story.failure_episodes ?? episodes.reduce((sum, episode) => sum + (episode.count || 1), 0);
    const atLeast = story.examined_all_failures === false ? "at least " : "";
    el("div", { class: "muted" }, box, told || atLeast ? `Failures: ${atLeast}${told}.` : "No failures.");
    const list = el("ol", { class: "episodes" }, box);
    for (const episode of episodes) {
      const item = el("li", {}, list);
      const t = episode.t_ns ?? 0;
      const link = el("a", { href: "#", class: "moment-link", "data-t-ns": t }, item,
        seconds(t) + (episode.count > 1 ? ` (×${episode.count}, last ${seconds(episode.last_t_ns)})` : ""));
      link.addEventListener("click", (e) => {
        e.preventDefault();
        if (episode.seq !== undefined && episode.seq !== null) this.pane.go({ count: episode.seq + 1 });
        else this.pane.go({ t_ns: t });
      });
      const sentence = episode.what_went_wrong ?? episode.sentence ?? episode.text ?? "";
      if (sentence) el("div", {}, item, sentence);
      const ways = Object.entries(episode.handled_so || {}).map(([way, n]) => `${n}× ${way}`);
      const handling = ways.length ? ways.join("; ")
        : Array.isArray(episode.handling) ? episode.handling.join("; ") : episode.handling;
      if (handling) el("div", { class: "muted" }, item, handling);
    }
    const listed = episodes.reduce((sum, episode) => sum + (episode.count || 1), 0);
    if ((story.failure_kinds || 0) > episodes.length) {
      el("div", { class: "muted" }, box, `… and ${story.failure_kinds - episodes.length} other ` +
        `kinds of failure (${told - listed} episodes).`);
    }
    if (story.guard_failures) {
      el("div", { class: "muted" }, box, `(${story.guard_failures} ` +
        `${story.guard_failures === 1 ? "failure" : "failures"} by design chose another branch.)`);
    }
    const subgoals = story.subgoals || [];
    if (!subgoals.length) return;
    el("div", { class: "muted" }, box, runs.length > 1 ? "Subgoals (in the goal's last run):" : "Subgoals:");
    const table = el("table", { class: "kv subgoals" }, box);
    for (const sub of subgoals) {
      const tr = el("tr", {}, table);
      const name = el("td", {}, tr, sub.subgoal ?? sub.name ?? "");
      if (sub.depth) name.style.paddingLeft = `${0.3 + sub.depth}em`;
      el("td", {}, tr, (sub.result ?? (sub.runs ? "not finished" : "not started")) +
        (sub.runs > 1 ? `, ${sub.runs} runs` : ""));
      const when = el("td", {}, tr);
      if (sub.start_ns !== undefined && sub.start_ns !== null) {
        const link = el("a", { href: "#", class: "moment-link" }, when,
          `${seconds(sub.start_ns)}` + (sub.end_ns !== null && sub.end_ns !== undefined
            ? ` – ${seconds(sub.end_ns)}` : ""));
        link.addEventListener("click", (e) => { e.preventDefault(); this.pane.go({ t_ns: sub.start_ns }); });
      }
    }
  }

  showAnswers(answers) {
    this.answerList.replaceChildren();
    for (const a of answers) {
      el("dt", {}, this.answerList, a.question);
      el("dd", {}, this.answerList, a.answer);
    }
  }

  showAsked(result) {
    this.askAnswer.textContent = result.answer;
  }

  showEvents(data, count) {
    this.eventList.replaceChildren();
    let now = null;
    for (const row of data.rows) {
      const who = this.name(row.uid);
      let text;
      if (row.kind === "status") text = `${who}  ${row.prev} \u2192 ${row.status}`;
      else if (row.kind === "write") {
        text = `${row.scope || "(root)"}.${row.key} = ${showValue(row.value)}  by ${who}`;
      } else text = `inserted ${who}`;
      const line = el("div", { "data-seq": row.seq }, this.eventList);
      el("span", { class: "seq" }, line, String(row.seq));
      el("span", { class: "when" }, line,
        `${seconds(row.t_ns)}${row.tick === undefined ? "" : " t" + row.tick}`);
      el("span", { class: "what" }, line, text);
      if (row.seq === count - 1) { line.classList.add("now"); now = line; }
      else if (row.seq >= count) line.classList.add("future");
      line.addEventListener("click", () => this.pane.go({ count: row.seq + 1 }));
    }
    if (now) {
      const box = this.eventList;
      box.scrollTop = now.offsetTop - box.offsetTop - box.clientHeight / 2;
    }
  }

  showBlackboard(entries) {
    this.board.replaceChildren();
    const head = el("tr", {}, this.board);
    for (const h of ["key", "value", "writer"]) el("th", {}, head, h);
    if (!entries.length) el("td", { colspan: 3, class: "muted" }, el("tr", {}, this.board), "(empty)");
    for (const e of entries) {
      const tr = el("tr", {}, this.board);
      el("td", {}, tr, (e.scope ? e.scope + "." : "") + e.key);
      el("code", {}, el("td", {}, tr), showValue(e.value));
      el("td", {}, tr, e.writer === null ? "" : `${this.name(e.writer)} @${e.seq}`);
    }
  }

  showNode(uid, state) {
    this.nodeBody.replaceChildren();
    this.nodeBody.className = "";
    if (uid === null) return;
    const n = this.pane.nodes.get(uid);
    el("div", {}, this.nodeBody, `${n.name || n.type}`).style.fontWeight = "600";
    el("div", { class: "muted" }, this.nodeBody,
      `${n.type} \u00b7 ${n.kind} \u00b7 #${uid} \u00b7 ${state.status[uid] || "IDLE"}`);
    el("div", { class: "muted" }, this.nodeBody, n.path);
    const ports = Object.entries(n.ports);
    if (!ports.length) return;
    const table = el("table", { class: "kv ports" }, this.nodeBody);
    const head = el("tr", {}, table);
    for (const h of ["port", "as written", "blackboard now"]) el("th", {}, head, h);
    for (const [port, p] of ports) {
      const tr = el("tr", {}, table);
      el("td", {}, tr, `${port} (${p.dir})`);
      el("td", {}, tr, p.value);
      const key = /^\s*\{(.*)\}\s*$/.exec(p.value);
      const name = key ? key[1].trim() : null;
      const found = key ? (state.blackboard.find((b) => b.key === name && b.scope === n.scope) ||
        state.blackboard.find((b) => b.key === name)) : null;
      el("code", {}, el("td", {}, tr), key ? (found ? showValue(found.value) : "(unset)") : "");
    }
  }
}
