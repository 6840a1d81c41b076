// The review page's behaviour: plain DOM, no framework and no build step, so
// the page runs from the package with no internet.  Every text from the
// workspace (documents, drafts, messages) goes in through textContent, never
// as HTML: corpus passages are third-party text.
"use strict";

(() => {
  const $ = (id) => document.getElementById(id);

  // How long typing must pause before an edited axiom is checked again: a
  // check starts the reasoner, so not on every keystroke.
  const RECHECK_AFTER_MS = 1500;

  const state = {
    filter: "pending",
    queue: [],
    selected: null, // candidate id
    view: null, // CandidateView of the selected candidate
    checks: new Map(), // axiom text -> CheckReport, for the selected candidate
    checkSeq: 0, // only the newest check's answer is shown
    recheckTimer: null,
    previewSeq: 0,
  };

  // -- talking to the server ------------------------------------------------

  async function api(method, path, body) {
    const init = { method, headers: { Accept: "application/json" } };
    // Mounted in `virf serve` (at /review/), the service's API key, if one
    // was entered on its page, goes along; relative paths keep both mounts working.
    const key = sessionStorage.getItem("virf-api-key");
    if (key) init.headers["X-API-Key"] = key;
    if (body !== undefined) {
      init.headers["Content-Type"] = "application/json";
      init.body = JSON.stringify(body);
    }
    let response;
    try {
      response = await fetch(path, init);
    } catch (err) {
      throw new Error(`the review server cannot be reached (${err.message}); is 'virf kb review' still running?`);
    }
    let data = null;
    try {
      data = await response.json();
    } catch (_) {
      data = null;
    }
    if (!response.ok) {
      // {"status": "BAD_INPUT" | "ERROR", "error": "one line"}, as the service answers.
      const said = data && typeof data.error === "string" ? data.error : response.statusText;
      const err = new Error(said || `HTTP ${response.status}`);
      err.status = response.status;
      throw err;
    }
    return data;
  }

  function showError(err) {
    $("banner-text").textContent = err instanceof Error ? err.message : String(err);
    $("banner").hidden = false;
  }

  function clearError() {
    $("banner").hidden = true;
    $("banner-text").textContent = "";
  }

  function notify(text) {
    const box = $("notice");
    box.textContent = text;
    box.hidden = false;
  }

  // -- small DOM helpers ----------------------------------------------------

  function el(tag, attrs, ...children) {
    const node = document.createElement(tag);
    for (const [key, value] of Object.entries(attrs || {})) {
      if (value === null || value === undefined || value === false) continue;
      if (key === "class") node.className = value;
      else if (key === "text") node.textContent = value;
      else node.setAttribute(key, value === true ? "" : String(value));
    }
    for (const child of children) {
      if (child === null || child === undefined) continue;
      node.append(child instanceof Node ? child : document.createTextNode(String(child)));
    }
    return node;
  }

  // The address of a web page, or null: only an absolute http(s) URL becomes
  // a link (a "javascript:" or "data:" one would run in the page's origin).
  function webAddress(url) {
    if (typeof url !== "string" || !url) return null;
    try {
      const parsed = new URL(url);
      return (parsed.protocol === "http:" || parsed.protocol === "https:") && parsed.host
        ? parsed.href
        : null;
    } catch {
      return null; // relative or malformed: no base to resolve it against
    }
  }

  function badge(status) {
    return el("span", { class: `badge ${status}`, "data-testid": "status-badge", text: status });
  }

  function passBadge(passed) {
    if (passed === null || passed === undefined) {
      return el("span", { class: "badge unchecked", text: "not checked" });
    }
    return passed
      ? el("span", { class: "badge pass", text: "checks pass" })
      : el("span", { class: "badge fail", text: "checks fail" });
  }

  function when(iso) {
    if (!iso) return "";
    const d = new Date(iso);
    return Number.isNaN(d.getTime()) ? iso : d.toLocaleString();
  }

  // -- the queue ------------------------------------------------------------

  async function loadQueue() {
    const status = state.filter === "pending" ? "pending" : "all";
    const items = await api("GET", `api/candidates?status=${status}`);
    // Pending first (the work left), then by id.
    const rank = { pending: 0, accepted: 1, rejected: 2 };
    items.sort((a, b) => (rank[a.status] - rank[b.status]) || (a.id - b.id));
    state.queue = items;
    renderQueue();
  }

  function renderQueue() {
    const list = $("queue");
    list.replaceChildren();
    for (const c of state.queue) {
      const button = el(
        "button",
        {
          type: "button",
          class: "queue-item",
          "data-testid": `queue-item-${c.id}`,
          "data-id": c.id,
          "data-status": c.status,
          "aria-current": c.id === state.selected ? "true" : "false",
        },
        el("span", { class: "qid", text: `#${c.id}` }),
        el("span", { class: "qname", text: c.name }),
        el(
          "span",
          { class: "qmeta" },
          badge(c.status),
          passBadge(c.passed),
          c.origin === "answer" ? el("span", { class: "badge learned", "data-testid": "learned-badge", text: "learned from an answer" }) : null,
          el("span", { text: c.category }),
          el("span", { text: `· ${c.drafter}` }),
        ),
      );
      button.addEventListener("click", () => select(c.id));
      list.append(el("li", {}, button));
    }
    $("queue-empty").hidden = state.queue.length > 0;
  }

  function moveSelection(step) {
    const buttons = [...document.querySelectorAll(".queue-item")];
    if (buttons.length === 0) return;
    let index = buttons.findIndex((b) => b === document.activeElement);
    if (index < 0) index = buttons.findIndex((b) => Number(b.dataset.id) === state.selected);
    const next = buttons[Math.min(buttons.length - 1, Math.max(0, index + step))];
    next.focus();
    select(Number(next.dataset.id));
  }

  // -- one candidate --------------------------------------------------------

  async function select(id) {
    clearError();
    try {
      const view = await api("GET", `api/candidates/${id}`);
      state.selected = id;
      state.view = view;
      state.checks = new Map();
      if (view.check) state.checks.set(view.check.axiom, view.check);
      renderQueue();
      renderCandidate();
    } catch (err) {
      showError(err);
    }
  }

  function draftAxiom() {
    return state.view ? state.view.rule.definition : "";
  }

  function decided() {
    return Boolean(state.view && state.view.decision);
  }

  function renderCandidate() {
    const view = state.view;
    $("placeholder").hidden = true;
    $("candidate").hidden = false;
    $("cand-id").textContent = `#${view.summary.id}`;
    $("rule-name").textContent = view.rule.name;
    const status = $("cand-status");
    status.className = `badge ${view.summary.status}`;
    status.textContent = view.summary.status;

    const learned = view.learned;
    $("rule-heading").textContent = learned ? "Learned class" : "Rule";
    $("axiom-hint").textContent = learned
      ? `the superclasses of ${learned.class_name} (${learned.class_name} SubClassOf …), Manchester syntax`
      : "Manchester syntax";
    if (learned) renderLearned(view);
    else renderFacts(view);
    if (learned) renderAnswers(learned);
    else renderEvidence(view.evidence);
    renderDecision(view.decision);

    const axiom = $("axiom");
    if (view.decision) {
      axiom.value = view.decision.axiom || (view.check ? view.check.axiom : draftAxiom());
    } else {
      // A stored check of an edited axiom is the reviewer's latest work.
      axiom.value = view.check ? view.check.axiom : draftAxiom();
    }
    axiom.readOnly = decided();
    $("check-btn").disabled = decided();
    $("reset-btn").hidden = decided();
    $("decide-box").hidden = decided();
    $("reason").value = "";
    $("check-state").textContent = "";
    // What accepting would change is moot once decided; a stored preview stays shown.
    $("preview-row").hidden = decided();
    $("preview-section").hidden = decided() && !view.preview;
    renderPreview(view.preview);
    showCheckFor(axiom.value);
  }

  function renderFacts(view) {
    const r = view.rule;
    const s = view.summary;
    const rows = [
      ["category", r.category],
      ["danger level", r.danger_level],
      ["kind", r.kind],
      ["checked at", r.check_at],
      ["description", r.description],
      ["safety warning", r.safety_warning, "warning"],
      ["trigger reason", r.trigger_reason],
      ["suggestion", r.suggestion],
      ["drafted axiom", r.definition, "mono"],
      ["drafted by", `${s.drafter}${s.query ? ` for the query "${s.query}"` : ""}, ${when(s.created_at)}`],
    ];
    showFacts(rows, "rule");
  }

  // A class learned from a user's answers about an object the knowledge base
  // did not know: what was learned, and from which answers.
  function renderLearned(view) {
    const l = view.learned;
    const rows = [
      ["learned class", l.class_name],
      ["written in the scene as", l.words.join(", ")],
      ["what WordNet suggested", l.reading],
      ["axioms as learned", l.axioms.join("\n"), "mono"],
      ["learned from", `answers by ${l.who} on ${when(l.when)} about ${l.instances.join(", ")} in scene ${l.scene_name} (SHA-256 ${l.scene_sha256.slice(0, 16)}…)`],
      ["plan", l.plan.join("; ")],
      ["no longer assumed once accepted", l.unconfirmed.join("; ")],
    ];
    showFacts(rows, "learned");
  }

  // The candidate's facts as a definition list: [label, value, class] rows,
  // each value's test id named after its label.
  function showFacts(rows, prefix) {
    const list = $("rule-facts");
    list.replaceChildren();
    for (const [label, value, cls] of rows) {
      const key = label.replaceAll(" ", "-");
      list.append(
        el("dt", { text: label }),
        el("dd", { class: cls || null, "data-testid": `${prefix}-${key}`, text: value || "—" }),
      );
    }
  }

  function renderAnswers(learned) {
    const list = $("evidence");
    list.replaceChildren();
    for (const a of learned.answers) {
      list.append(
        el(
          "li",
          { "data-testid": "learned-answer", "data-key": a.key },
          el("div", { class: "src" }, `${learned.who} was asked `, el("code", { text: `[${a.key}]` })),
          el("blockquote", {}, a.question, " ", el("strong", { "data-testid": "learned-answer-value", text: a.answer })),
          el("div", { class: "small", "data-testid": "learned-answer-effect", text: a.effect }),
        ),
      );
    }
  }

  function renderEvidence(evidence) {
    const list = $("evidence");
    list.replaceChildren();
    if (evidence.length === 0) {
      list.append(el("li", { class: "missing", text: "This candidate cites no passage." }));
      return;
    }
    for (const e of evidence) {
      if (!e.found) {
        list.append(
          el(
            "li",
            { class: "missing", "data-testid": "evidence-missing", "data-passage": e.passage_id },
            el("strong", { text: e.passage_id }),
            " — this passage is not in the corpus any more: the rule's evidence is missing.",
          ),
        );
        continue;
      }
      const href = webAddress(e.url);
      const title = href
        ? el("a", { href, rel: "noreferrer noopener", target: "_blank", text: e.document_title || e.document_id })
        : el("strong", { text: e.document_title || e.document_id });
      list.append(
        el(
          "li",
          { "data-testid": "evidence-item", "data-passage": e.passage_id },
          el(
            "div",
            { class: "src" },
            title,
            e.publisher ? ` — ${e.publisher}` : "",
            e.section ? ` — § ${e.section}` : "",
            " ",
            el("code", { text: `[${e.passage_id}]` }),
          ),
          el("blockquote", { text: e.text }),
        ),
      );
    }
  }

  function renderDecision(decision) {
    const box = $("decision-box");
    box.hidden = !decision;
    if (!decision) return;
    const verb = decision.decision === "accept" ? "Accepted" : "Rejected";
    const edit = decision.decision === "accept" && decision.edit !== "none" ? ` with a ${decision.edit} edit` : "";
    const secs = decision.seconds === null || decision.seconds === undefined ? "" : ` after ${Math.round(decision.seconds)} s of review`;
    const reason = decision.reason ? ` Reason: ${decision.reason}` : "";
    $("decision-text").textContent = `${verb}${edit} by ${decision.reviewer} on ${when(decision.decided_at)}${secs}.${reason}`;
  }

  // -- checks ---------------------------------------------------------------

  function showCheckFor(text) {
    if (decided()) {
      // The record of what was checked before the decision, not a draft to compare.
      $("check-items").style.opacity = "1";
      renderReport(state.view.check);
      if (!state.view.check) {
        $("check-summary").className = "check-summary stale";
        $("check-summary").textContent = "No check was recorded for this candidate.";
      }
      return;
    }
    const report = state.checks.get(text);
    const summary = $("check-summary");
    if (!report) {
      summary.className = "check-summary stale";
      summary.textContent = state.checks.size
        ? "The axiom was edited since the last check; press Check (or pause typing) to check it."
        : "Not checked yet: press Check.";
      $("check-state").textContent = "";
      // The last results stay visible below, greyed as stale, for comparison.
      $("check-items").style.opacity = state.checks.size ? "0.55" : "1";
      if (!state.checks.size) renderReport(null);
    } else {
      $("check-items").style.opacity = "1";
      renderReport(report);
    }
    updateDecisionButtons();
  }

  function renderReport(report) {
    const summary = $("check-summary");
    const items = $("check-items");
    const related = $("related");
    const tbody = $("terms").querySelector("tbody");
    items.replaceChildren();
    related.replaceChildren();
    tbody.replaceChildren();
    $("normalised").textContent = "";
    $("module-text").textContent = "";
    $("terms-caption").textContent = "";
    if (!report) return;

    summary.className = `check-summary ${report.passed ? "pass" : "fail"}`;
    summary.textContent = report.passed
      ? `All checks pass (layer: ${report.layer}; checked ${when(report.checked_at)}).`
      : `A check failed: this axiom cannot be accepted as it is (checked ${when(report.checked_at)}).`;
    for (const item of report.items) {
      const cls = item.ok ? "ok" : item.severity;
      const sym = item.ok ? "✓" : item.severity === "error" ? "✗" : item.severity === "warning" ? "!" : "i";
      items.append(
        el(
          "li",
          { class: cls, "data-testid": "check-item", "data-ok": String(item.ok), "data-severity": item.severity },
          el("span", { class: "sym", "aria-hidden": "true", text: sym }),
          el("strong", { text: item.name }),
          item.message ? `: ${item.message}` : "",
        ),
      );
    }
    const rel = report.related;
    const groups = [
      ["equivalent to", rel.equivalent],
      ["a special case of (subsumed by)", rel.subsumed_by],
      ["generalises (subsumes)", rel.subsumes],
    ];
    const shown = groups.filter(([, names]) => names.length);
    if (shown.length === 0) {
      related.append(el("p", { class: "related muted", text: "Related USCs: none; this concept overlaps no existing rule." }));
    } else {
      const list = el("ul", { class: "related" });
      for (const [label, names] of shown) {
        list.append(el("li", {}, `This concept is ${label}: `, el("code", { text: names.join(", ") })));
      }
      related.append(el("p", { text: "Related USCs:" }), list);
    }
    $("normalised").textContent = report.normalised;
    $("module-text").textContent = report.module_text;

    $("terms-caption").textContent = `A term is matched to the vocabulary when its similarity is at least ${report.threshold}.`;
    for (const t of report.terms) {
      const alternatives = t.alternatives.map(([name, score]) => `${name} (${score.toFixed(2)})`).join(", ");
      const below = t.score !== null && t.score !== undefined && t.score < report.threshold;
      tbody.append(
        el(
          "tr",
          { class: `match-${t.match}${below ? " below" : ""}`, "data-testid": "term-row" },
          el("td", { class: "mono", text: t.term }),
          el("td", { text: t.role }),
          el("td", { text: t.match }),
          el("td", { class: "mono", text: t.chosen }),
          el("td", { class: "num", text: t.score === null || t.score === undefined ? "—" : t.score.toFixed(2) }),
          el("td", { class: "mono", text: alternatives || "—" }),
          el("td", { text: t.match === "new" ? `${t.parent || "?"} / ${t.layer || "?"}` : "—" }),
        ),
      );
    }
    if (report.terms.length === 0) {
      tbody.append(el("tr", {}, el("td", { colspan: "7", class: "muted", text: "No terms to match." })));
    }
  }

  async function runCheck() {
    if (!state.view || decided()) return;
    clearTimeout(state.recheckTimer);
    const id = state.view.summary.id;
    const text = $("axiom").value;
    if (!text.trim()) {
      showError("the axiom is empty: write a Manchester-syntax class expression first");
      return;
    }
    const seq = ++state.checkSeq;
    $("check-state").textContent = "checking…";
    $("check-btn").disabled = true;
    try {
      const report = await api("POST", `api/candidates/${id}/check`, { axiom: text });
      if (!state.view || state.view.summary.id !== id) return;
      state.checks.set(text, report);
      if (seq === state.checkSeq) {
        clearError();
        showCheckFor($("axiom").value);
        $("check-state").textContent = "checked";
      }
      // The queue shows whether the latest check passed.
      loadQueue().catch(showError);
    } catch (err) {
      if (seq === state.checkSeq) {
        showError(err);
        $("check-state").textContent = "the check could not run";
      }
    } finally {
      if (seq === state.checkSeq) $("check-btn").disabled = decided();
    }
  }

  function onAxiomEdited() {
    showCheckFor($("axiom").value);
    clearTimeout(state.recheckTimer);
    if ($("axiom").value.trim()) state.recheckTimer = setTimeout(runCheck, RECHECK_AFTER_MS);
  }

  // -- preview --------------------------------------------------------------

  function renderPreview(preview) {
    const box = $("preview");
    box.replaceChildren();
    if (!preview) return;
    const scenes = preview.scenes ? `, ${preview.scenes} scene(s) it was learned from` : "";
    const head = `Computed ${when(preview.computed_at)} for ${preview.examples} example(s)${scenes} and ${preview.tasks} task(s)` +
      (preview.tasks_file ? ` from ${preview.tasks_file}` : "") + ".";
    box.append(el("p", { class: "muted", text: head }));
    if (preview.kb_test) {
      box.append(el("p", { "data-testid": "preview-kb-test", text: preview.kb_test }));
      for (const f of preview.kb_test_failures || []) {
        box.append(el("p", { class: "check-summary fail", "data-testid": "preview-kb-test-failure", text: `New failure: ${f}` }));
      }
    }
    if (preview.error) {
      box.append(el("p", { class: "check-summary fail", "data-testid": "preview-error", text: preview.error }));
    }
    if (preview.changes.length === 0) {
      box.append(el("p", { "data-testid": "preview-none", text: "No verdict changes." }));
      return;
    }
    const list = el("ol", { class: "changes" });
    for (const c of preview.changes) {
      list.append(
        el(
          "li",
          { "data-testid": "preview-change" },
          el("code", { text: c.item }),
          c.instruction ? ` “${c.instruction}”` : "",
          ": ",
          el("strong", { text: c.before }),
          " → ",
          el("strong", { text: c.after }),
          c.concept ? el("span", { class: "muted" }, " (", el("code", { text: c.concept }), ")") : "",
        ),
      );
    }
    box.append(list);
  }

  async function runPreview() {
    if (!state.view) return;
    const id = state.view.summary.id;
    const text = $("axiom").value;
    const seq = ++state.previewSeq;
    const button = $("preview-btn");
    button.disabled = true;
    $("preview").replaceChildren(el("p", { class: "muted", text: "computing the effect… (seconds)" }));
    try {
      const body = { axiom: text === draftAxiom() ? null : text };
      const preview = await api("POST", `api/candidates/${id}/preview`, body);
      if (seq === state.previewSeq && state.view && state.view.summary.id === id) renderPreview(preview);
    } catch (err) {
      if (seq === state.previewSeq) {
        $("preview").replaceChildren();
        showError(err);
      }
    } finally {
      if (seq === state.previewSeq) button.disabled = false;
    }
  }

  // -- decisions ------------------------------------------------------------

  function updateDecisionButtons() {
    if (!state.view) return;
    const text = $("axiom").value;
    const edited = text.trim() !== draftAxiom().trim();
    const failed = (axiom) => {
      const report = state.checks.get(axiom);
      return Boolean(report && !report.passed);
    };
    const accept = $("accept-btn");
    const acceptEdited = $("accept-edited-btn");
    accept.disabled = failed(draftAxiom());
    accept.title = accept.disabled ? "The drafted axiom failed a check." : "Accept the axiom as it was drafted.";
    acceptEdited.disabled = !edited || failed(text);
    acceptEdited.title = !edited ? "Edit the axiom first." : failed(text) ? "The edited axiom failed a check." : "Accept the axiom as edited above.";
  }

  async function decide(decision, axiom) {
    if (!state.view) return;
    const id = state.view.summary.id;
    const body = { decision, reason: null, axiom };
    if (decision === "reject") {
      const reason = $("reason").value.trim();
      if (!reason) {
        showError("a rejection needs a reason: write it in the field next to Reject");
        $("reason").focus();
        return;
      }
      body.reason = reason;
    }
    for (const b of ["accept-btn", "accept-edited-btn", "reject-btn"]) $(b).disabled = true;
    try {
      const result = await api("POST", `api/candidates/${id}/decision`, body);
      clearError();
      notify(`Candidate #${id} ${result.decision === "accept" ? "accepted" : "rejected"}.`);
      await Promise.all([loadQueue(), loadRules()]);
      await select(id);
    } catch (err) {
      showError(err);
      if (err.status === 409) {
        // Someone else decided it: show what they decided.
        await Promise.all([loadQueue(), select(id)]).catch(showError);
      }
    } finally {
      $("reject-btn").disabled = false;
      updateDecisionButtons();
    }
  }

  // -- accepted rules -------------------------------------------------------

  async function loadRules() {
    const rules = await api("GET", "api/rules");
    const tbody = $("rules").querySelector("tbody");
    tbody.replaceChildren();
    for (const r of rules) {
      tbody.append(
        el(
          "tr",
          { "data-testid": "rule-row", "data-name": r.name },
          el("td", { text: r.id }),
          el("td", { text: r.name }),
          el("td", { text: r.layer }),
          el("td", { text: r.category }),
          el("td", { class: "mono", text: r.axiom }),
          el("td", { class: "mono", text: r.evidence.join(", ") }),
          el("td", { text: r.drafter }),
          el("td", { text: r.reviewer }),
          el("td", { text: r.edit }),
          el("td", { text: when(r.decided_at) }),
          el("td", { class: "num", text: `#${r.candidate_id}` }),
        ),
      );
    }
    $("rules-count").textContent = `(${rules.length})`;
    $("rules-empty").hidden = rules.length > 0;
    $("rules").hidden = rules.length === 0;
  }

  // -- wiring ---------------------------------------------------------------

  function wire() {
    $("banner-close").addEventListener("click", clearError);
    for (const radio of document.querySelectorAll("input[name=filter]")) {
      radio.addEventListener("change", () => {
        state.filter = radio.value;
        loadQueue().catch(showError);
      });
    }
    $("queue-refresh").addEventListener("click", () => {
      Promise.all([loadQueue(), loadRules()]).catch(showError);
    });
    $("queue").addEventListener("keydown", (event) => {
      const step = { ArrowDown: 1, j: 1, ArrowUp: -1, k: -1 }[event.key];
      if (step) {
        event.preventDefault();
        moveSelection(step);
      }
    });
    const axiom = $("axiom");
    axiom.addEventListener("input", onAxiomEdited);
    axiom.addEventListener("keydown", (event) => {
      if (event.key === "Enter" && (event.ctrlKey || event.metaKey)) {
        event.preventDefault();
        runCheck();
      }
    });
    $("check-btn").addEventListener("click", runCheck);
    $("reset-btn").addEventListener("click", () => {
      axiom.value = draftAxiom();
      onAxiomEdited();
    });
    $("preview-btn").addEventListener("click", runPreview);
    $("accept-btn").addEventListener("click", () => decide("accept", null));
    $("accept-edited-btn").addEventListener("click", () => decide("accept", $("axiom").value));
    $("reject-btn").addEventListener("click", () => decide("reject", null));
    $("reason").addEventListener("keydown", (event) => {
      if (event.key === "Enter") {
        event.preventDefault();
        decide("reject", null);
      }
    });
    document.addEventListener("keydown", (event) => {
      if (event.altKey && (event.key === "r" || event.key === "R")) {
        event.preventDefault();
        $("rules-heading").focus();
        $("rules-heading").scrollIntoView();
      }
    });
  }

  async function start() {
    wire();
    try {
      await Promise.all([loadQueue(), loadRules()]);
      if (state.queue.length) await select(state.queue[0].id);
    } catch (err) {
      showError(err);
    }
    document.body.dataset.ready = "true";
  }

  start();
})();
