// The VIRF service page: verify a scene and plan, draw the state at the
// dangerous step, answer open questions, browse the rules, follow a
// tutor–apprentice planning run.  Plain DOM code,
// no framework and no build step, so the page works offline from the wheel.
"use strict";

(() => {
  const byId = (id) => document.querySelector(`[data-testid="${id}"]`);
  const SVG = "http://www.w3.org/2000/svg";
  const KEY_STORE = "virf-api-key";
  // Phases whose finding is about the state before the step's action (the
  // snapshot that carries the action about to happen), not the state after it.
  const BEFORE_ACTION = new Set(["action", "precondition", "missing-object"]);
  // Question kinds an answer turns into scene data (virf.planner.questions.SETTLEABLE).
  const SETTLEABLE = new Set(["material", "fill", "contents", "confirm", "which", "where", "contradiction"]);

  // What the current report was made from: drawing a state or answering a
  // question must use these, not whatever the text boxes hold by now.
  let current = null;
  let rules = null;
  // The service's health: whether it can learn from answers (a workspace).
  let service = null;
  // Answers about objects the knowledge base does not know, that can be
  // kept for later scenes: the scene and plan they were given for (before
  // any answer), the answers that settled questions, and the scene's
  // open-world objects (instance -> the class as written).
  let learning = null;
  let ruleShown = null;
  // Responses that arrive after a newer request was sent are dropped.
  let verifySeq = 0;
  let stateSeq = 0;

  // ------------------------------------------------------------ helpers
  function el(tag, attrs, ...children) {
    const node = document.createElement(tag);
    for (const [name, value] of Object.entries(attrs || {})) {
      if (value === null || value === undefined || value === false) continue;
      if (name === "class") node.className = value;
      else if (name === "text") node.textContent = value;
      else node.setAttribute(name, value === true ? "" : String(value));
    }
    for (const child of children) {
      if (child === null || child === undefined) continue;
      node.append(child instanceof Node ? child : document.createTextNode(String(child)));
    }
    return node;
  }

  function svgEl(tag, attrs) {
    const node = document.createElementNS(SVG, tag);
    for (const [name, value] of Object.entries(attrs || {})) {
      if (value === null || value === undefined) continue;
      node.setAttribute(name, String(value));
    }
    return node;
  }

  // Each tab keeps its own error, so one tab's failure is never read as
  // another's; an action of the tab clears it.  ``page`` holds what concerns
  // every tab (the service unreachable, its key refused): it shows in all of
  // them, under a tab's own error.
  const errors = { page: "", verify: "", rules: "", plan: "" };
  let activeTab = "verify";

  function showError(where, message) {
    errors[where] = message;
    renderBanner();
  }

  function clearError(where) {
    errors[where] = "";
    renderBanner();
  }

  function renderBanner() {
    const where = errors[activeTab] ? activeTab : "page";
    const message = errors[where];
    const banner = byId("error-banner");
    banner.hidden = !message;
    banner.dataset.tab = message ? where : "";
    byId("error-text").textContent = message;
    // A tab whose error is not on show says it has one.
    for (const tab of document.querySelectorAll(".tab[data-tab]")) {
      const held = Boolean(errors[tab.dataset.tab]) && tab.dataset.tab !== activeTab;
      tab.dataset.error = String(held);
      tab.title = held ? "an error happened on this tab" : "";
    }
  }

  function dismissError() {
    clearError(errors[activeTab] ? activeTab : "page");
  }

  class ApiError extends Error {}

  async function api(method, path, body) {
    const headers = { Accept: "application/json" };
    const key = byId("api-key").value.trim();
    if (key) headers["X-API-Key"] = key;
    if (body !== undefined) headers["Content-Type"] = "application/json";
    let response;
    try {
      response = await fetch(path, {
        method,
        headers,
        // A string is a body already written as JSON.
        body: body === undefined || typeof body === "string" ? body : JSON.stringify(body),
      });
    } catch (exc) {
      throw new ApiError(`the server did not answer (${exc.message})`);
    }
    let data = null;
    try {
      data = await response.json();
    } catch (exc) {
      data = null;
    }
    if (!response.ok) {
      const said = data && typeof data.error === "string" ? data.error : null;
      throw new ApiError(said || `${response.status} ${response.statusText} from ${path}`);
    }
    return data;
  }

  const factText = (f) => `${f.subject} ${f.predicate} ${f.object}`;
  const factKey = (f) => `${f.subject}\u0000${f.predicate}\u0000${f.object}`;
  const stateOf = (v) => (BEFORE_ACTION.has(v.phase) ? Math.max(0, v.step - 1) : v.step);

  function busy(on) {
    byId("busy").hidden = !on;
    byId("verify-button").disabled = on;
  }

  // ------------------------------------------------------------ tabs
  function showTab(name) {
    activeTab = name;
    for (const tab of document.querySelectorAll(".tab")) {
      tab.setAttribute("aria-selected", String(tab.dataset.tab === name));
    }
    for (const panel of document.querySelectorAll(".panel")) {
      panel.hidden = panel.dataset.panel !== name;
    }
    renderBanner();
    if (name === "rules") loadRules();
  }

  // ------------------------------------------------------------ examples
  async function loadExamples() {
    const select = byId("example-select");
    let examples = [];
    try {
      examples = await api("GET", "/v1/examples");
    } catch (exc) {
      showError("verify", exc.message);
      return;
    }
    select.replaceChildren();
    if (!examples.length) {
      select.append(el("option", { value: "", text: "(no bundled examples on this server)" }));
      select.disabled = true;
      return;
    }
    select.disabled = false;
    select.append(el("option", { value: "", text: "(choose a bundled example)" }));
    for (const ex of examples) {
      select.append(el("option", { value: ex.name, title: ex.description, text: ex.name }));
    }
  }

  // The example the boxes were last filled from, as loaded: the label names
  // it only while both boxes still hold it character for character.
  let loadedExample = null; // { name, description, scene, plan }
  let exampleSeq = 0;

  function syncExampleLabel() {
    const select = byId("example-select");
    const description = byId("example-description");
    const ex = loadedExample;
    const same = ex !== null && byId("scene-input").value === ex.scene && byId("plan-input").value === ex.plan;
    const listed = ex !== null && [...select.options].some((o) => o.value === ex.name);
    select.value = same && listed ? ex.name : "";
    description.dataset.state = ex === null ? "" : same ? "example" : "edited";
    description.textContent =
      ex === null ? "" : same ? ex.description : `edited from the example ${ex.name}; choose it again to start over`;
  }

  async function pickExample() {
    const name = byId("example-select").value;
    const seq = ++exampleSeq;
    if (!name) {
      // Nothing chosen: the label goes back to what the boxes hold.
      syncExampleLabel();
      return;
    }
    clearError("verify");
    byId("example-description").textContent = "loading…";
    byId("example-description").dataset.state = "loading";
    try {
      const ex = await api("GET", `/v1/examples/${encodeURIComponent(name)}`);
      if (seq !== exampleSeq) return;
      const scene = JSON.stringify(ex.scene, null, 2);
      byId("scene-input").value = scene;
      byId("plan-input").value = ex.plan;
      loadedExample = { name, description: ex.description, scene, plan: ex.plan };
    } catch (exc) {
      if (seq !== exampleSeq) return;
      showError("verify", exc.message);
    }
    syncExampleLabel();
  }

  async function readFileInto(input, target) {
    const file = input.files && input.files[0];
    if (!file) return;
    try {
      byId(target).value = await file.text();
      loadedExample = null;
      syncExampleLabel();
    } catch (exc) {
      showError("verify", `could not read ${file.name}: ${exc.message}`);
    }
  }

  // ------------------------------------------------------------ verify
  // A request body with the scene as it was typed, not as the browser read
  // it: the server refuses what JSON.parse lets by (a key twice, the later
  // value silently winning), as the CLI refuses it in a file.  ``sceneText``
  // has been parsed as a JSON object; ``fields`` is not empty.
  function sceneBody(sceneText, fields) {
    return `{"scene": ${sceneText}, ${JSON.stringify(fields).slice(1)}`;
  }

  function readInputs() {
    const sceneText = byId("scene-input").value;
    const plan = byId("plan-input").value;
    if (!sceneText.trim()) throw new ApiError("paste or upload a scene (JSON) first");
    if (!plan.trim()) throw new ApiError("paste or upload a plan first");
    let scene;
    try {
      scene = JSON.parse(sceneText);
    } catch (exc) {
      throw new ApiError(`the scene is not valid JSON: ${exc.message}`);
    }
    if (scene === null || typeof scene !== "object" || Array.isArray(scene)) {
      throw new ApiError("the scene must be a JSON object with instances and assertions");
    }
    return { scene, plan, sceneText };
  }

  async function verify(keepNotice) {
    clearError("verify");
    if (!keepNotice) {
      byId("answers-notice").hidden = true;
      // A new scene or plan: earlier answers are not about it.
      learning = null;
      byId("learn-box").hidden = true;
      byId("learn-result").hidden = true;
    }
    // Counted before the input is read: an answer still on its way for an
    // earlier input must not land over this attempt, failed or not.
    const seq = ++verifySeq;
    let input;
    try {
      input = readInputs();
    } catch (exc) {
      verifyFailed(exc.message);
      busy(false);
      return;
    }
    busy(true);
    try {
      const report = await api("POST", "/v1/verify", sceneBody(input.sceneText, { plan: input.plan }));
      if (seq !== verifySeq) return;
      current = { scene: input.scene, plan: input.plan, report };
      renderReport(report);
      // Before the result is revealed: the box stands between the verdict and the trace.
      offerLearning();
      revealResult();
      await drawState(defaultState(report));
    } catch (exc) {
      if (seq === verifySeq) verifyFailed(exc.message);
    } finally {
      if (seq === verifySeq) busy(false);
    }
  }

  // The result on show was made from an earlier input: left as it is, it
  // would read as the answer to what the boxes hold now.
  function verifyFailed(message) {
    showError("verify", message);
    if (current) markStale(true);
  }

  // A stale result is greyed, says why, and takes no clicks: its questions
  // and steps belong to an input the boxes no longer hold.
  function markStale(on) {
    const result = byId("result");
    result.classList.toggle("stale", on);
    result.dataset.stale = String(on);
    byId("stale-notice").hidden = !on;
    byId("result-body").inert = on;
  }

  // After a verify, the verdict and the dangerous step must be in view without
  // the user scrolling: the trace scrolls (in its own box) to that step, and
  // the page scrolls as little as it takes to show both, never past the verdict.
  function revealResult() {
    // The user went to another tab meanwhile: nothing of this one is laid out.
    if (activeTab !== "verify") return;
    const line = byId("verdict-line").getBoundingClientRect();
    let bottom = line.bottom;
    const row = byId("trace").querySelector("tr[data-dangerous=true]");
    if (row) {
      const box = byId("trace-box");
      const head = byId("trace").querySelector("thead").getBoundingClientRect().height;
      const rowTop = row.getBoundingClientRect().top - box.getBoundingClientRect().top + box.scrollTop;
      if (rowTop + row.offsetHeight > box.scrollTop + box.clientHeight || rowTop - head < box.scrollTop) {
        box.scrollTop = rowTop - head;
      }
      bottom = Math.max(bottom, row.getBoundingClientRect().bottom);
    }
    const margin = 8;
    if (line.top >= margin && bottom <= window.innerHeight - margin) return;
    window.scrollBy(0, Math.min(line.top - margin, bottom - window.innerHeight + margin));
  }

  // The state to draw first: the dangerous step's, else the plan's last.
  function defaultState(report) {
    const lead =
      report.violations.find((v) => v.step === report.dangerous_step && v.definite) ||
      report.violations.find((v) => v.step === report.dangerous_step) ||
      report.violations[0];
    if (lead) return stateOf(lead);
    const simulated = report.trace.filter((t) => t.outcome !== "not-simulated").length;
    return report.status === "SAFE" ? simulated : 0;
  }

  function renderReport(report) {
    markStale(false);
    byId("result").hidden = false;
    const verdict = byId("verdict");
    verdict.textContent = report.status;
    verdict.dataset.status = report.status;
    // Where the plan goes wrong, next to the verdict: the trace row may be far below.
    const where = byId("verdict-step");
    const step = report.dangerous_step;
    where.hidden = step === null;
    where.dataset.step = step === null ? "" : String(step);
    where.textContent = step === null ? "" : `at step ${step}: ${report.action || "the scene before the plan"}`;
    byId("reason").textContent = report.reason;
    renderTrace(report);
    renderNotes(report);
    renderQuestions(report);
    renderViolations(report);
    const suggestion = report.suggestion || "";
    byId("suggestion").textContent = suggestion;
    byId("suggestion-box").hidden = !suggestion;
  }

  function renderTrace(report) {
    const body = byId("trace").querySelector("tbody");
    body.replaceChildren();
    // A new trace starts at its first step, not where the last one was scrolled.
    byId("trace-box").scrollTop = 0;
    const rows = [
      { step: 0, action: "(the scene before the plan)", outcome: "", findings: [], added: [], removed: [] },
      ...report.trace,
    ];
    for (const t of rows) {
      const dangerous = t.step === report.dangerous_step;
      const changes = [...t.added.map((a) => `+ ${a}`), ...t.removed.map((r) => `− ${r}`)];
      const row = el(
        "tr",
        {
          "data-testid": "trace-step",
          "data-step": t.step,
          "data-outcome": t.outcome,
          "data-dangerous": dangerous ? "true" : "false",
          class: dangerous ? `dangerous ${report.status === "UNKNOWN" ? "unknown" : ""}` : "",
          title: t.outcome === "not-simulated" ? "not simulated: no state to draw" : "draw this state",
        },
        el("td", { text: String(t.step) }),
        el("td", { class: "mono", text: t.action }),
        el("td", { class: `outcome-${t.outcome}` }, t.outcome, ...t.findings.map((f) => el("div", { class: "finding" }, ...camelBreaks(f)))),
        el("td", { class: "changes", text: changes.join("\n") }),
      );
      row.style.whiteSpace = "pre-line";
      if (t.outcome !== "not-simulated") {
        row.addEventListener("click", () => drawState(stateForRow(report, t.step)));
      }
      body.append(row);
    }
  }

  // A rule's CamelCase name with line-break chances between its words, so a
  // narrow column wraps it between words rather than inside one.
  function camelBreaks(name) {
    const parts = name.split(/(?=[A-Z][a-z])/);
    return parts.flatMap((p, i) => (i ? [document.createElement("wbr"), p] : [p]));
  }

  // A row's findings decide which snapshot shows them; otherwise the state after the step.
  function stateForRow(report, step) {
    const here = report.violations.find((v) => v.step === step);
    return here ? stateOf(here) : step;
  }

  function factList(facts, testid) {
    return el("ul", {}, ...facts.map((f) => el("li", { "data-testid": testid, class: "mono", text: factText(f) })));
  }

  function renderViolations(report) {
    const box = byId("violations");
    box.replaceChildren();
    byId("no-violations").hidden = report.violations.length > 0;
    report.violations.forEach((v, i) => {
      const openRule = el("button", { type: "button", class: "linkish small", "data-testid": "open-rule", text: "rule ›" });
      openRule.addEventListener("click", () => {
        showTab("rules");
        selectRuleWhenLoaded(v.id);
      });
      const card = el(
        "div",
        {
          class: `violation ${v.definite ? "" : "possible"}`,
          "data-testid": "violation",
          "data-id": v.id,
          "data-index": i,
        },
        el("h3", {}, el("span", { "data-testid": "violation-rule", text: v.id }), " ", openRule),
        el(
          "div",
          { class: "meta" },
          el("span", { class: "badge", "data-testid": "violation-category", text: v.category }),
          el("span", { class: `badge ${v.danger_level}`, "data-testid": "violation-danger", text: `danger: ${v.danger_level}` }),
          el("span", { class: "badge", text: `step ${v.step} · ${v.phase}` }),
          el("span", { class: "badge", text: v.definite ? "definite" : "possible" }),
        ),
        el("div", { "data-testid": "violation-message", text: v.message }),
      );
      if (v.triggering_facts.length) {
        card.append(el("div", { class: "label", text: "Triggering facts" }), factList(v.triggering_facts, "trigger-fact"));
      }
      if (v.assumed_facts.length) {
        card.append(el("div", { class: "label", text: "Assumed facts (not known)" }), factList(v.assumed_facts, "assumed-fact"));
      }
      if (v.as_written.length) {
        card.append(el("div", { class: "label", text: "As the scene wrote them" }), factList(v.as_written, "as-written-fact"));
      }
      if (v.background.length) {
        card.append(
          el("div", { class: "label", text: "Background knowledge" }),
          el(
            "ul",
            {},
            ...v.background.map((b) =>
              el("li", { "data-testid": "background-axiom" }, el("span", { class: "mono", text: b.text }), el("span", { class: "src", text: ` (${b.id}; ${b.source})` })),
            ),
          ),
        );
      }
      if (v.suggestion) {
        card.append(el("div", { class: "label", text: "Suggestion" }), el("div", { "data-testid": "violation-suggestion", text: v.suggestion }));
      }
      card.append(el("div", { class: "src", text: `Source: ${v.source}` }));
      card.addEventListener("click", (event) => {
        if (event.target.closest("button")) return;
        drawState(stateOf(v), i);
      });
      box.append(card);
    });
  }

  // How the scene and plan were read where not word for word: an object of a
  // class the knowledge base does not know, a plan line in everyday words.
  function renderNotes(report) {
    const notes = report.notes || [];
    const list = byId("notes-list");
    list.replaceChildren(...notes.map((n) => el("li", { "data-testid": "note", text: n })));
    byId("notes").hidden = notes.length === 0;
  }

  // ------------------------------------------------------------ questions
  // The value a question's form sends for an option: a contradiction's
  // options are facts, and the server accepts their number.
  const optionValue = (q, option, i) => (q.kind === "contradiction" ? String(i + 1) : option);

  // An answer as the person chose it: a contradiction's number is its fact.
  function answerText(q, value) {
    if (q && q.kind === "contradiction" && /^[0-9]+$/.test(value)) {
      return q.options[Number(value) - 1] || value;
    }
    return value;
  }

  function renderQuestions(report) {
    const section = byId("questions");
    const form = byId("questions-form");
    form.replaceChildren();
    section.hidden = report.questions.length === 0;
    let answerable = 0;
    for (const q of report.questions) {
      const settleable = SETTLEABLE.has(q.kind);
      const id = `q-${form.childElementCount}`;
      const row = el(
        "div",
        { class: `question ${settleable ? "" : "readonly"}`, "data-testid": "question", "data-key": q.key, "data-kind": q.kind },
        el("label", { class: "qtext", for: settleable ? id : null, text: q.text }),
      );
      if (settleable) {
        answerable += 1;
        let control;
        if (q.options.length) {
          control = el("select", { id, "data-testid": "answer", "data-key": q.key }, el("option", { value: "", text: "(leave open)" }));
          q.options.forEach((o, i) => control.append(el("option", { value: optionValue(q, o, i), text: o })));
        } else {
          control = el("input", { id, type: "text", "data-testid": "answer", "data-key": q.key, placeholder: "leave blank to keep it open" });
        }
        row.append(el("div", {}, control));
      } else {
        row.append(el("div", { class: "muted small", text: "No scene datum settles this one: the plan itself must change." }));
      }
      form.append(row);
    }
    if (answerable) {
      form.append(el("button", { type: "submit", class: "primary", "data-testid": "answer-button", text: "Answer and verify again" }));
    }
  }

  async function submitAnswers(event) {
    event.preventDefault();
    clearError("verify");
    if (!current) return;
    const answers = {};
    for (const control of byId("questions-form").querySelectorAll("[data-testid=answer]")) {
      const value = control.value.trim();
      if (value) answers[control.dataset.key] = value;
    }
    if (!Object.keys(answers).length) {
      showError("verify", "answer at least one question (the others may stay open)");
      return;
    }
    busy(true);
    const asked = current.report.questions;
    if (!learning) learning = { scene: current.scene, plan: current.plan, answers: {}, openWorld: null, about: new Set(), sent: false };
    try {
      const update = await api("POST", "/v1/apply-answers", { scene: current.scene, plan: current.plan, answers });
      // The first answers' scene is the one as given: its open-world objects.
      if (learning.openWorld === null) learning.openWorld = update.open_world || {};
      for (const key of update.applied) {
        learning.answers[key] = answers[key];
        const q = asked.find((x) => x.key === key);
        const subject = q && (q.fact ? q.fact.subject : q.subject);
        if (subject && subject in learning.openWorld) learning.about.add(subject);
      }
      byId("scene-input").value = JSON.stringify(update.scene, null, 2);
      byId("plan-input").value = current.plan;
      syncExampleLabel();
      // Keys are for machines: the notice names each question as the report asked it.
      const item = (testid, key, answered) => {
        const q = asked.find((x) => x.key === key);
        const given = answered ? [" ", el("strong", { text: answerText(q, answers[key]) })] : [];
        return el("li", { "data-testid": testid, "data-key": key }, q ? q.text : key, ...given);
      };
      const notice = byId("answers-notice");
      notice.replaceChildren(
        el("div", {
          text: update.applied.length
            ? "Your answers settled these questions; the scene above now says so:"
            : "Your answers settled none of the questions; the scene above is unchanged.",
        }),
        el("ul", {}, ...update.applied.map((key) => item("settled-question", key, true))),
        update.unsettled.length ? el("div", { text: "Not settled by these answers, still open:" }) : null,
        el("ul", {}, ...update.unsettled.map((key) => item("unsettled-question", key, Boolean(answers[key])))),
      );
      notice.hidden = false;
    } catch (exc) {
      showError("verify", exc.message);
      busy(false);
      return;
    }
    busy(false);
    await verify(true);
  }

  // ------------------------------------------------------------ learning
  // Answers about objects the knowledge base does not know can be kept for
  // later scenes when the service has a knowledge workspace.
  function offerLearning() {
    const box = byId("learn-box");
    if (!learning || !learning.about.size || !(service && service.learn)) {
      box.hidden = true;
      return;
    }
    const objects = [...learning.about].sort().map((o) => `${o} (a '${learning.openWorld[o]}')`);
    const kinds = [...new Set([...learning.about].map((o) => learning.openWorld[o]))].join(", ");
    byId("learn-text").textContent =
      `Your answers were about ${objects.length === 1 ? "an object" : "objects"} the knowledge base does not know: ${objects.join(", ")}. ` +
      `Remembered, they become proposed knowledge about every ${kinds}: a reviewer checks it on the Review page, and only then do later scenes use it.`;
    byId("learn-button").disabled = learning.sent;
    box.hidden = false;
  }

  async function sendLearning() {
    clearError("verify");
    if (!learning || learning.sent) return;
    const who = byId("learn-who").value.trim();
    if (!who) {
      showError("verify", "say who you are (your name is kept with your answers)");
      byId("learn-who").focus();
      return;
    }
    const button = byId("learn-button");
    button.disabled = true;
    byId("learn-busy").hidden = false;
    const result = byId("learn-result");
    try {
      const got = await api("POST", "/v1/learn", { scene: learning.scene, plan: learning.plan, answers: learning.answers, who });
      learning.sent = true;
      const items = got.candidates.map((c) => {
        const state = c.passed ? "its checks pass" : `a check failed: ${c.problems[0] || "see the Review page"}`;
        return el(
          "li",
          { "data-testid": "learned-candidate", "data-id": c.id, "data-name": c.class_name },
          el("strong", { text: `#${c.id} ${c.class_name}` }),
          `: ${c.axioms.join("; ")} (${state})`,
        );
      });
      const review = el("a", { href: "review/", "data-testid": "learn-review-link", text: "Review page" });
      const where = got.applies_here
        ? ["Once a reviewer accepts it on the ", review, ", later scenes use it."]
        : ["A reviewer can accept it on the ", review, "; this service verifies without that workspace, so its verdicts will not change (start it with --kb on the same folder)."];
      result.replaceChildren(
        el("div", { text: got.candidates.length ? "Sent for review:" : "Nothing to remember: the answers confirmed nothing about a kind of object." }),
        el("ul", {}, ...items),
        ...got.skipped.map((s) => el("div", { class: "small", text: `Not kept: ${s}` })),
        got.candidates.length ? el("div", {}, ...where) : "",
      );
      result.hidden = false;
    } catch (exc) {
      showError("verify", exc.message);
      button.disabled = false;
    } finally {
      byId("learn-busy").hidden = true;
    }
  }

  // ------------------------------------------------------------ scene graph
  // Draws state ``index``, highlighting the facts of its violations, or of
  // violation number ``only`` alone.
  async function drawState(index, only) {
    if (!current) return;
    const seq = ++stateSeq;
    const { scene, plan, report } = current;
    try {
      const snap = await api("POST", "/v1/state", { scene, plan, step: index });
      if (seq !== stateSeq || current.report !== report) return;
      const chosen = only === undefined ? null : report.violations[only];
      const highlights = chosen ? [chosen] : report.violations.filter((v) => stateOf(v) === index);
      renderGraph(snap, highlights);
      for (const card of byId("violations").querySelectorAll("[data-testid=violation]")) {
        card.classList.toggle("selected", chosen !== null && Number(card.dataset.index) === only);
      }
      for (const row of byId("trace").querySelectorAll("tbody tr")) {
        row.classList.toggle("shown", Number(row.dataset.step) === stateRowOf(report, index));
      }
    } catch (exc) {
      if (seq === stateSeq) showError("verify", exc.message);
    }
  }

  // The trace row a drawn state belongs to (a before-action snapshot belongs to its action).
  function stateRowOf(report, index) {
    const v = report.violations.find((x) => stateOf(x) === index && BEFORE_ACTION.has(x.phase));
    return v ? v.step : index;
  }

  function renderGraph(snap, violations) {
    const wanted = new Map();
    for (const v of violations) for (const f of v.triggering_facts) wanted.set(factKey(f), f);
    const found = new Set();

    // Objects are boxes: every subject of a fact. A relation between two
    // of them is an arrow; anything else (types, states, materials, data
    // values, closed lists) is a line inside its subject's box.
    const nodes = new Map();
    for (const f of snap.facts) {
      if (!nodes.has(f.subject)) nodes.set(f.subject, { name: f.subject, types: [], attrs: [], hl: false });
    }
    const edges = [];
    for (const f of snap.facts) {
      const node = nodes.get(f.subject);
      const key = factKey(f);
      const hl = wanted.has(key);
      if (hl) found.add(key);
      const assumed = f.provenance === "assumed";
      if (f.predicate === "rdf:type") {
        node.types.push({ text: `is a ${f.object}`, hl, assumed, fact: f });
      } else if (f.kind === "object" && nodes.has(f.object) && f.object !== f.subject) {
        edges.push({ from: f.subject, to: f.object, label: f.predicate, hl, assumed, fact: f });
        if (hl) nodes.get(f.object).hl = true;
      } else {
        node.attrs.push({ text: `${f.predicate} ${f.object}`, hl, assumed, fact: f });
      }
      if (hl) node.hl = true;
    }
    for (const v of violations) if (nodes.has(v.subject)) nodes.get(v.subject).hl = true;

    const ordered = orderNodes(nodes, edges);
    const CH = 7.3; // px per character of the 12px monospace font
    const LINE = 15;
    for (const n of ordered) {
      const lines = [n.name, ...n.types.map((t) => t.text), ...n.attrs.map((a) => a.text)];
      n.w = Math.ceil(Math.max(...lines.map((l) => l.length)) * CH + 16);
      n.h = lines.length * LINE + 10;
    }
    const maxW = Math.max(120, ...ordered.map((n) => n.w));
    const maxH = Math.max(40, ...ordered.map((n) => n.h));
    // An ellipse wide enough that neighbouring boxes do not overlap.
    const count = ordered.length;
    const rx = count > 1 ? (maxW * count) / 4.5 + 60 : 0;
    const ry = count > 1 ? (maxH * count) / 4.5 + 40 : 0;
    ordered.forEach((n, i) => {
      const angle = -Math.PI / 2 + (2 * Math.PI * i) / Math.max(1, count);
      n.x = rx * Math.cos(angle);
      n.y = ry * Math.sin(angle);
    });
    const pad = 24;
    const minX = Math.min(...ordered.map((n) => n.x - n.w / 2)) - pad;
    const maxX = Math.max(...ordered.map((n) => n.x + n.w / 2)) + pad;
    const minY = Math.min(...ordered.map((n) => n.y - n.h / 2)) - pad;
    const maxY = Math.max(...ordered.map((n) => n.y + n.h / 2)) + pad;
    const width = Math.max(200, maxX - minX);
    const height = Math.max(120, maxY - minY);

    const svg = svgEl("svg", {
      viewBox: `${minX} ${minY} ${width} ${height}`,
      width: Math.round(width),
      height: Math.round(height),
      role: "img",
      "aria-label": `Scene graph of state ${snap.step}`,
      "data-testid": "graph-svg",
    });
    const defs = svgEl("defs");
    for (const [id, colour] of [["arrow", "#8a96a3"], ["arrow-hl", "#d6336c"], ["arrow-assumed", "#9a6200"]]) {
      const marker = svgEl("marker", { id, viewBox: "0 0 10 10", refX: 10, refY: 5, markerWidth: 7, markerHeight: 7, orient: "auto-start-reverse" });
      marker.append(svgEl("path", { d: "M0,0 L10,5 L0,10 z", fill: colour }));
      defs.append(marker);
    }
    svg.append(defs);

    const byName = new Map(ordered.map((n) => [n.name, n]));
    const pairCount = new Map();
    const labels = [];
    for (const e of edges) {
      const a = byName.get(e.from);
      const b = byName.get(e.to);
      const start = border(a, b.x - a.x, b.y - a.y);
      const end = border(b, a.x - b.x, a.y - b.y);
      const pair = [e.from, e.to].sort().join("\u0000");
      const nth = pairCount.get(pair) || 0;
      pairCount.set(pair, nth + 1);
      const g = svgEl("g", {
        class: `edge ${e.hl ? "hl" : ""} ${e.assumed ? "assumed" : ""}`,
        "data-testid": "graph-edge",
        "data-fact": factText(e.fact),
        "data-highlighted": e.hl ? "true" : "false",
      });
      const marker = e.hl ? "arrow-hl" : e.assumed ? "arrow-assumed" : "arrow";
      g.append(svgEl("line", { x1: start.x, y1: start.y, x2: end.x, y2: end.y, "marker-end": `url(#${marker})` }));
      const title = svgEl("title");
      title.textContent = `${factText(e.fact)} (${e.fact.provenance})`;
      g.append(title);
      svg.append(g);
      // Labels of several relations between one pair are stacked, not overprinted.
      const label = svgEl("text", {
        x: (start.x + end.x) / 2,
        y: (start.y + end.y) / 2 - 4 + nth * 13,
        "text-anchor": "middle",
        class: `edge-label ${e.hl ? "hl" : ""}`,
      });
      label.textContent = e.label;
      labels.push(label);
    }

    for (const n of ordered) {
      const g = svgEl("g", {
        class: `node ${n.hl ? "hl" : ""}`,
        "data-testid": "graph-node",
        "data-name": n.name,
        "data-highlighted": n.hl ? "true" : "false",
        transform: `translate(${n.x - n.w / 2},${n.y - n.h / 2})`,
      });
      g.append(svgEl("rect", { width: n.w, height: n.h, rx: 5 }));
      const lines = [
        { text: n.name, cls: "name" },
        ...n.types.map((t) => ({ ...t, cls: "type" })),
        ...n.attrs.map((a) => ({ ...a, cls: "attr" })),
      ];
      lines.forEach((line, i) => {
        const classes = [line.cls, line.assumed ? "assumed" : "", line.hl ? "hl" : ""].join(" ").trim();
        const t = svgEl("text", { x: 8, y: 18 + i * LINE, class: classes, "data-highlighted": line.hl ? "true" : "false" });
        t.textContent = line.text;
        if (line.fact) {
          const title = svgEl("title");
          title.textContent = `${factText(line.fact)} (${line.fact.provenance})`;
          t.append(title);
        }
        g.append(t);
      });
      svg.append(g);
    }
    // Relation names go last so no box hides one.
    const labelLayer = svgEl("g", { class: "labels" });
    labelLayer.append(...labels);
    svg.append(labelLayer);

    byId("graph").replaceChildren(svg);
    const action = snap.action ? ` · next action: ${snap.action}` : "";
    const which = snap.step === 0 ? "the scene before the plan" : `after step ${snap.step}`;
    const lit = violations.length ? ` · highlighted: the facts of ${violations.map((v) => v.id).join(", ")}` : "";
    byId("graph-caption").textContent = `State ${snap.step} (${which})${action} · ${ordered.length} objects, ${snap.facts.length} facts${lit}`;
    byId("graph-caption").dataset.step = String(snap.step);

    const missing = [...wanted.entries()].filter(([k]) => !found.has(k)).map(([, f]) => factText(f));
    const box = byId("graph-missing");
    box.hidden = missing.length === 0;
    box.textContent = missing.length ? `Triggering facts not among this state's assertions: ${missing.join("; ")}` : "";
  }

  // Connected objects sit next to each other on the ellipse: breadth-first
  // from the best-connected object, ties broken by name, so the drawing is
  // the same every time.
  function orderNodes(nodes, edges) {
    const adjacent = new Map([...nodes.keys()].map((n) => [n, new Set()]));
    for (const e of edges) {
      adjacent.get(e.from).add(e.to);
      adjacent.get(e.to).add(e.from);
    }
    const names = [...nodes.keys()].sort();
    const byDegree = [...names].sort((a, b) => adjacent.get(b).size - adjacent.get(a).size || (a < b ? -1 : 1));
    const seen = new Set();
    const out = [];
    for (const start of byDegree) {
      if (seen.has(start)) continue;
      const queue = [start];
      seen.add(start);
      while (queue.length) {
        const name = queue.shift();
        out.push(nodes.get(name));
        for (const next of [...adjacent.get(name)].sort()) {
          if (!seen.has(next)) {
            seen.add(next);
            queue.push(next);
          }
        }
      }
    }
    return out;
  }

  // Where the ray from a box's centre in direction (dx, dy) leaves the box.
  function border(n, dx, dy) {
    const hw = n.w / 2 + 2;
    const hh = n.h / 2 + 2;
    const t = Math.min(dx ? hw / Math.abs(dx) : Infinity, dy ? hh / Math.abs(dy) : Infinity);
    return { x: n.x + dx * (Number.isFinite(t) ? t : 0), y: n.y + dy * (Number.isFinite(t) ? t : 0) };
  }

  // ------------------------------------------------------------ rules
  const RULE_FIELDS = [
    ["definition", "Definition"],
    ["category", "Category"],
    ["danger_level", "Danger level"],
    ["kind", "Kind"],
    ["check_at", "Checked"],
    ["description", "Description"],
    ["safety_warning", "Safety warning"],
    ["trigger_reason", "Triggered when"],
    ["suggestion", "Suggestion"],
    ["source", "Sources"],
    ["question", "Question asked"],
    ["generalizes", "Generalises"],
    ["module", "Module"],
  ];
  let pendingRule = null;

  async function loadRules() {
    if (rules !== null) return;
    rules = [];
    try {
      rules = await api("GET", "/v1/rules");
    } catch (exc) {
      rules = null;
      showError("rules", exc.message);
      return;
    }
    clearError("rules");
    filterRules();
    if (pendingRule) selectRule(pendingRule);
    else if (rules.length) selectRule(rules[0].id);
  }

  function selectRuleWhenLoaded(id) {
    pendingRule = id;
    if (rules && rules.length) selectRule(id);
  }

  function filterRules() {
    const words = byId("rule-search").value.toLowerCase().split(/\s+/).filter(Boolean);
    const list = byId("rule-list");
    list.replaceChildren();
    const shown = (rules || []).filter((r) => {
      const hay = RULE_FIELDS.map(([k]) => r[k]).concat([r.id, r.name]).join("\n").toLowerCase();
      return words.every((w) => hay.includes(w));
    });
    for (const r of shown) {
      const item = el(
        "button",
        { type: "button", class: "rule-item", "data-testid": "rule-item", "data-id": r.id, "aria-current": String(r.id === ruleShown) },
        el("span", { class: "rid" }, ...camelBreaks(r.id)),
        el("span", { class: "rmeta", text: `${r.category} · ${r.danger_level} · ${r.kind}` }),
      );
      item.addEventListener("click", () => selectRule(r.id));
      list.append(el("li", {}, item));
    }
    byId("rule-count").textContent = `${shown.length} of ${(rules || []).length} rules`;
  }

  function selectRule(id) {
    const rule = (rules || []).find((r) => r.id === id);
    if (!rule) return;
    pendingRule = null;
    ruleShown = id;
    for (const item of byId("rule-list").querySelectorAll(".rule-item")) {
      item.setAttribute("aria-current", String(item.dataset.id === id));
    }
    const dl = el("dl");
    for (const [key, label] of RULE_FIELDS) {
      if (!rule[key]) continue;
      dl.append(el("dt", { text: label }), el("dd", { "data-testid": `rule-${key.replace("_", "-")}`, class: key === "definition" ? "mono" : "", text: rule[key] }));
    }
    byId("rule-detail").replaceChildren(el("h2", { "data-testid": "rule-name", text: rule.id }), dl);
  }

  // ------------------------------------------------------------ plan runs
  // A tutor–apprentice run (POST /v1/plan) followed through its event
  // stream.  fetch() rather than EventSource: EventSource cannot send the
  // X-API-Key header a keyed service needs.
  const OUTCOME_STATUS = { APPROVED: "SAFE", APPROVED_UNVERIFIED: "UNKNOWN", TASK_REJECTED: "UNSAFE" };
  let planRun = null; // { id, answers, abort }
  let planSeq = 0;
  // The run's questions by key, as the tutor worded them: its turns name
  // questions by key, which is for machines.
  let planAsked = new Map();

  function keyHeaders(extra) {
    const headers = { ...extra };
    const key = byId("api-key").value.trim();
    if (key) headers["X-API-Key"] = key;
    return headers;
  }

  function planState(state) {
    const badge = byId("plan-state");
    badge.hidden = !state;
    badge.textContent = state || "";
    badge.dataset.state = state || "";
    // Only while the run is being created: a new run may replace a running one
    // (that one fails closed on its own if nobody answers it).
    byId("plan-start").disabled = state === "starting";
  }

  function readPlanInputs() {
    const instruction = byId("plan-instruction").value.trim();
    const sceneText = byId("plan-scene").value;
    if (!instruction) throw new ApiError("write the instruction for the robot first");
    if (!sceneText.trim()) throw new ApiError("paste or upload a scene (JSON) for the run first");
    let scene;
    try {
      scene = JSON.parse(sceneText);
    } catch (exc) {
      throw new ApiError(`the run's scene is not valid JSON: ${exc.message}`);
    }
    if (scene === null || typeof scene !== "object" || Array.isArray(scene)) {
      throw new ApiError("the run's scene must be a JSON object with instances and assertions");
    }
    const fields = { instruction };
    const planner = byId("plan-planner").value.trim();
    if (planner) fields.planner = planner;
    fields.task_id = byId("plan-task-id").value.trim() || "task";
    const maxIter = byId("plan-max-iter").value.trim();
    if (maxIter) {
      const n = Number(maxIter);
      if (!Number.isInteger(n) || n < 1 || n > 20) throw new ApiError("max iterations must be a whole number from 1 to 20");
      fields.max_iter = n;
    }
    return sceneBody(sceneText, fields);
  }

  function resetPlanView() {
    planAsked = new Map();
    byId("plan-run").hidden = false;
    byId("dialogue").replaceChildren();
    byId("plan-outcome-box").hidden = true;
    byId("plan-final-box").hidden = true;
    byId("plan-questions").hidden = true;
    byId("plan-questions-form").replaceChildren();
    byId("plan-run-id").textContent = "";
  }

  async function startPlan() {
    clearError("plan");
    let body;
    try {
      body = readPlanInputs();
    } catch (exc) {
      showError("plan", exc.message);
      return;
    }
    if (planRun) planRun.abort.abort();
    planRun = null;
    const seq = ++planSeq;
    resetPlanView();
    planState("starting");
    let started;
    try {
      started = await api("POST", "/v1/plan", body);
    } catch (exc) {
      if (seq !== planSeq) return;
      planState("");
      byId("plan-run").hidden = true;
      showError("plan", exc.message);
      return;
    }
    if (seq !== planSeq) return;
    planRun = { id: started.id, run: started.run, answers: started.answers, abort: new AbortController() };
    byId("plan-run-id").textContent = `run ${started.id}`;
    planState(started.state);
    await followPlan(seq, planRun, started.events);
  }

  async function followPlan(seq, run, eventsUrl) {
    let finished = false;
    try {
      const response = await fetch(eventsUrl, {
        headers: keyHeaders({ Accept: "text/event-stream" }),
        signal: run.abort.signal,
      });
      if (!response.ok) {
        let said = null;
        try {
          said = (await response.json()).error;
        } catch (exc) {
          said = null;
        }
        throw new ApiError(said || `${response.status} ${response.statusText} from ${eventsUrl}`);
      }
      const reader = response.body.pipeThrough(new TextDecoderStream()).getReader();
      let buffer = "";
      for (;;) {
        const { value, done } = await reader.read();
        if (done) break;
        // The SSE format allows \r\n and \r line ends; one form is easier to split.
        buffer += value.replace(/\r\n?/g, "\n");
        let cut;
        while ((cut = buffer.indexOf("\n\n")) >= 0) {
          const block = buffer.slice(0, cut);
          buffer = buffer.slice(cut + 2);
          const message = parseEvent(block);
          if (message === null || seq !== planSeq) continue;
          finished = onPlanEvent(message.event, message.data) || finished;
        }
      }
    } catch (exc) {
      if (exc.name === "AbortError" || seq !== planSeq) return;
      showError("plan", exc instanceof ApiError ? exc.message : `the run's event stream broke off (${exc.message})`);
    }
    if (seq !== planSeq || finished) return;
    // The stream ended early (a proxy, a restart): the run's own state says where it is.
    try {
      const state = await api("GET", run.run);
      if (seq !== planSeq) return;
      if (state.result) onPlanEvent("result", state.result);
      else if (state.error) onPlanEvent("error", { error: state.error });
      else {
        planState(state.state);
        showError("plan", `the run's event stream ended while the run was ${state.state}; reload its state with ${run.run}`);
      }
    } catch (exc) {
      if (seq === planSeq) showError("plan", exc.message);
    }
  }

  // One server-sent event: its `event:` name and its `data:` lines joined;
  // comment lines (": keep-alive") are not events.
  function parseEvent(block) {
    let event = "message";
    const data = [];
    for (const line of block.split("\n")) {
      if (!line || line.startsWith(":")) continue;
      const colon = line.indexOf(":");
      const field = colon < 0 ? line : line.slice(0, colon);
      let value = colon < 0 ? "" : line.slice(colon + 1);
      if (value.startsWith(" ")) value = value.slice(1);
      if (field === "event") event = value;
      else if (field === "data") data.push(value);
    }
    if (!data.length) return null;
    try {
      return { event, data: JSON.parse(data.join("\n")) };
    } catch (exc) {
      showError("plan", `the run sent an event that is not JSON (${event})`);
      return null;
    }
  }

  // Returns whether the run is over.
  function onPlanEvent(event, data) {
    if (event === "turn") {
      addTurn(data);
      if (planRun && byId("plan-state").dataset.state !== "running") planState("running");
      byId("plan-questions").hidden = true;
    } else if (event === "questions") {
      planState("waiting");
      renderPlanQuestions(data);
    } else if (event === "result") {
      byId("plan-questions").hidden = true;
      planState("done");
      renderOutcome(data);
      return true;
    } else if (event === "error") {
      byId("plan-questions").hidden = true;
      planState("failed");
      showError("plan", `the run failed: ${data.error}`);
      return true;
    }
    return false;
  }

  const SPEAKERS = { user: "You", apprentice: "Apprentice", tutor: "Tutor" };

  function addTurn(turn) {
    const box = byId("dialogue");
    let group = box.querySelector(`[data-testid=iteration][data-iteration="${turn.iteration}"]`);
    if (!group) {
      group = el(
        "section",
        { class: "iteration", "data-testid": "iteration", "data-iteration": turn.iteration },
        el("h3", { text: `Iteration ${turn.iteration + 1}` }),
      );
      box.append(group);
    }
    const head = el(
      "div",
      { class: "turn-head" },
      el("span", { class: "speaker", "data-testid": "turn-speaker", text: SPEAKERS[turn.speaker] || turn.speaker }),
      el("span", { class: "badge", "data-testid": "turn-kind", text: turn.kind }),
    );
    if (turn.status) {
      head.append(el("span", { class: "verdict small-verdict", "data-testid": "turn-status", "data-status": turn.status, text: turn.status }));
    }
    remember(turn.data && turn.data.questions);
    const body =
      (turn.kind === "answers" && answersList(turn.text)) ||
      (turn.kind === "unsettled" && unsettledList(turn.data)) ||
      // A correction lists whole plans, one step a line, as a proposal does.
      (turn.kind === "proposal" || turn.kind === "corrections"
        ? el("pre", { class: "plan-text", "data-testid": "turn-text", text: turn.text })
        : el("div", { class: "turn-text", "data-testid": "turn-text", text: turn.text }));
    const extra = [];
    if (turn.kind === "report" && turn.data && turn.data.suggestion) {
      extra.push(el("div", { class: "small turn-note", "data-testid": "turn-suggestion", text: `Suggestion: ${turn.data.suggestion}` }));
    }
    group.append(
      el(
        "article",
        {
          class: `turn ${turn.speaker}`,
          "data-testid": "turn",
          "data-speaker": turn.speaker,
          "data-kind": turn.kind,
          "data-status": turn.status || "",
        },
        head,
        body,
        ...extra,
      ),
    );
    body.scrollIntoView({ block: "nearest" });
  }

  function remember(questions) {
    if (!Array.isArray(questions)) return;
    for (const q of questions) if (q && typeof q.key === "string") planAsked.set(q.key, q);
  }

  const askedText = (key) => (planAsked.has(key) ? planAsked.get(key).text : key);

  // The answers turn carries the answers as JSON {key: answer}: each is shown
  // under its question's words.  Null when it is not that JSON (shown as it came).
  function answersList(text) {
    let given;
    try {
      given = JSON.parse(text);
    } catch (exc) {
      return null;
    }
    if (!given || typeof given !== "object" || Array.isArray(given)) return null;
    const entries = Object.entries(given);
    if (!entries.length) {
      return el("div", { class: "turn-text", "data-testid": "turn-text", text: "(no answers: every question stays open)" });
    }
    return el(
      "ul",
      { class: "turn-list", "data-testid": "turn-text" },
      ...entries.map(([key, value]) =>
        el("li", { "data-testid": "turn-answer", "data-key": key }, askedText(key), " ", el("strong", { text: answerText(planAsked.get(key), String(value)) })),
      ),
    );
  }

  // The questions still open when the tutor stops asking, each with why.
  function unsettledList(data) {
    const rows = data && Array.isArray(data.unsettled) ? data.unsettled : null;
    if (!rows) return null;
    return el(
      "div",
      { "data-testid": "turn-text" },
      el("div", { class: "turn-text", text: "Still open:" }),
      el(
        "ul",
        { class: "turn-list" },
        ...rows.map((r) => el("li", { "data-testid": "turn-unsettled", "data-key": r.key }, askedText(r.key), el("span", { class: "muted", text: ` (${r.why})` }))),
      ),
    );
  }

  function renderPlanQuestions(questions) {
    remember(questions);
    const section = byId("plan-questions");
    const form = byId("plan-questions-form");
    form.replaceChildren();
    questions.forEach((q, n) => {
      const id = `pq-${n}`;
      let control;
      if (q.options.length) {
        control = el("select", { id, "data-testid": "plan-answer", "data-key": q.key }, el("option", { value: "", text: "(leave open)" }));
        q.options.forEach((o, i) => control.append(el("option", { value: optionValue(q, o, i), text: o })));
      } else {
        control = el("input", { id, type: "text", "data-testid": "plan-answer", "data-key": q.key, placeholder: "leave blank to keep it open" });
      }
      form.append(
        el(
          "div",
          { class: "question", "data-testid": "plan-question", "data-key": q.key, "data-kind": q.kind },
          el("label", { class: "qtext", for: id, text: q.text }),
          el("div", {}, control),
        ),
      );
    });
    form.append(el("button", { type: "submit", class: "primary", "data-testid": "plan-answer-button", text: "Send answers" }));
    section.hidden = false;
  }

  async function submitPlanAnswers(event) {
    event.preventDefault();
    clearError("plan");
    if (!planRun) return;
    const answers = {};
    for (const control of byId("plan-questions-form").querySelectorAll("[data-testid=plan-answer]")) {
      const value = control.value.trim();
      if (value) answers[control.dataset.key] = value;
    }
    const button = byId("plan-answer-button");
    button.disabled = true;
    const run = planRun;
    try {
      // No answers at all is a valid reply: every question stays open.
      await api("POST", run.answers, { answers });
      if (run === planRun) byId("plan-questions").hidden = true;
    } catch (exc) {
      showError("plan", exc.message);
    } finally {
      button.disabled = false;
    }
  }

  function renderOutcome(result) {
    const outcome = byId("plan-outcome");
    outcome.textContent = result.outcome;
    outcome.dataset.status = OUTCOME_STATUS[result.outcome] || "ERROR";
    outcome.dataset.outcome = result.outcome;
    const rounds = result.iterations === 1 ? "1 iteration" : `${result.iterations} iterations`;
    byId("plan-reason").textContent = `${result.reason} · ${rounds}`;
    byId("plan-outcome-box").hidden = false;
    const plan = result.plan || [];
    byId("plan-final").textContent = plan.length ? plan.join("\n") : "(no plan)";
    byId("plan-final-box").hidden = false;
  }

  async function readPlanScene(input) {
    const file = input.files && input.files[0];
    if (!file) return;
    try {
      byId("plan-scene").value = await file.text();
    } catch (exc) {
      showError("plan", `could not read ${file.name}: ${exc.message}`);
    }
  }

  // ------------------------------------------------------------ start
  async function health() {
    try {
      const h = await api("GET", "/v1/health");
      service = h;
      byId("health").textContent = `${h.status} · scenario ${h.scenario} · ${h.engine} engine · ${h.rules} rules`;
      // The knowledge-acquisition review page, when the service has a workspace.
      byId("review-link").hidden = !h.review;
    } catch (exc) {
      byId("health").textContent = "";
      showError("page", exc.message);
    }
  }

  async function start() {
    const key = byId("api-key");
    key.value = sessionStorage.getItem(KEY_STORE) || "";
    key.addEventListener("change", async () => {
      sessionStorage.setItem(KEY_STORE, key.value.trim());
      // Another key: what the old one was refused is no tab's error any more.
      for (const where of Object.keys(errors)) errors[where] = "";
      renderBanner();
      rules = null;
      await Promise.all([health(), loadExamples()]);
      // The list was made again: it names the boxes' example again, if they hold one.
      syncExampleLabel();
      if (!byId("panel-rules").hidden) loadRules();
    });
    for (const tab of document.querySelectorAll(".tab")) {
      tab.addEventListener("click", () => showTab(tab.dataset.tab));
    }
    byId("error-close").addEventListener("click", dismissError);
    byId("example-select").addEventListener("change", pickExample);
    byId("scene-input").addEventListener("input", syncExampleLabel);
    byId("plan-input").addEventListener("input", syncExampleLabel);
    byId("scene-file").addEventListener("change", (e) => readFileInto(e.target, "scene-input"));
    byId("plan-file").addEventListener("change", (e) => readFileInto(e.target, "plan-input"));
    byId("verify-button").addEventListener("click", () => verify(false));
    byId("questions-form").addEventListener("submit", submitAnswers);
    byId("learn-button").addEventListener("click", sendLearning);
    byId("rule-search").addEventListener("input", filterRules);
    byId("plan-start").addEventListener("click", startPlan);
    byId("plan-questions-form").addEventListener("submit", submitPlanAnswers);
    byId("plan-scene-file").addEventListener("change", (e) => readPlanScene(e.target));
    byId("plan-scene-from-verify").addEventListener("click", () => {
      byId("plan-scene").value = byId("scene-input").value;
    });
    await Promise.all([health(), loadExamples()]);
    if (location.hash === "#rules") showTab("rules");
    if (location.hash === "#plan") showTab("plan");
    document.body.dataset.ready = "true";
  }

  start();
})();
