// Driving Arena pages: submit through the API and poll a submission's progress.
// The team token stays in this tab's sessionStorage and goes only into Authorization headers.
const Arena = (() => {
  const API = "/api/v1";
  const TOKEN_KEY = "arena-token";
  const ADMIN_TOKEN_KEY = "arena-admin-token";
  const $ = (id) => document.getElementById(id);
  const headers = (token) => ({ Authorization: `Bearer ${token}` });
  const FINISHED = ["scored", "failed", "rejected", "cancelled", "disqualified"];

  async function errorText(response) {
    try {
      const body = await response.json();
      return typeof body.detail === "string" ? body.detail : JSON.stringify(body.detail);
    } catch {
      return `${response.status} ${response.statusText}`;
    }
  }

  // Uploads left today in the chosen phase and track (needs the team token in this tab).
  async function triesLeft() {
    const token = $("token").value.trim();
    if (!token) { $("tries-left").hidden = true; return; }
    const response = await fetch(`${API}/team`, { headers: headers(token) });
    if (!response.ok) { $("tries-left").hidden = true; return; }
    const status = await response.json();
    const allowance = status.allowances.find(
      (a) => a.phase.name === $("phase").value && a.track === $("track").value);
    if (!allowance) { $("tries-left").hidden = true; return; }
    $("tries-left").textContent = `Team ${status.team}: ${allowance.tries_left_today} of ` +
      `${allowance.daily_quota} uploads left today in ${allowance.phase.name} / ` +
      `${allowance.track} (the count resets at 00:00 UTC).`;
    $("tries-left").hidden = false;
  }

  function submitForm() {
    const form = $("submit-form");
    $("token").value = sessionStorage.getItem(TOKEN_KEY) || "";
    for (const id of ["phase", "track", "token"]) $(id).addEventListener("change", triesLeft);
    // The chosen phase in full under the select (a phone cuts a long option).
    const details = JSON.parse($("phase").dataset.details);
    $("phase").addEventListener("change", () => {
      $("phase-detail").textContent = details[$("phase").value] || "";
    });
    triesLeft();
    form.addEventListener("submit", async (event) => {
      event.preventDefault();
      const token = $("token").value.trim();
      const data = new FormData();
      data.append("phase", $("phase").value);
      data.append("track", $("track").value);
      data.append("method_name", $("method_name").value);
      data.append("description", $("description").value);
      data.append("file", $("file").files[0]);
      $("submit-error").hidden = true;
      $("submit-button").disabled = true;
      $("submit-status").textContent = "Uploading…";
      try {
        const response = await fetch(`${API}/submissions`, {
          method: "POST", headers: headers(token), body: data,
        });
        if (!response.ok) {
          // The message says what to fix; a bare status code above it says nothing more.
          $("submit-status").textContent = response.status >= 500
            ? "The service failed to take the upload; please try again later." : "";
          $("submit-error").textContent = await errorText(response);
          $("submit-error").hidden = false;
          return;
        }
        sessionStorage.setItem(TOKEN_KEY, token);
        let submission = await response.json();
        // 202: received and stored; a job checks the zip in the sandbox. A rejection is shown
        // here, as the synchronous checks' messages are; once queued, its page takes over.
        if (submission.status === "validating") {
          $("submit-status").textContent = "Received; validating the zip (this takes a few seconds)…";
          submission = await untilValidated(submission.id, token);
        }
        if (submission.status === "rejected" || submission.status === "failed") {
          $("submit-status").textContent = `Rejected by its validation (${submission.status}).`;
          $("submit-error").textContent = submission.status_reason;
          $("submit-error").hidden = false;
          return;
        }
        window.location.href = `/submissions/${submission.id}`;
      } catch (error) {
        $("submit-status").textContent = "Upload failed.";
        $("submit-error").textContent = String(error);
        $("submit-error").hidden = false;
      } finally {
        $("submit-button").disabled = false;
      }
    });
  }

  async function untilValidated(id, token) {
    // The validation ends within the intake's time limits; past ten minutes the page shows it.
    const deadline = Date.now() + 600_000;
    for (;;) {
      await new Promise((resolve) => setTimeout(resolve, 1000));
      const response = await fetch(`${API}/submissions/${id}`, { headers: headers(token) });
      if (!response.ok) throw new Error(await errorText(response));
      const submission = await response.json();
      if (submission.status !== "validating" || Date.now() > deadline) return submission;
    }
  }

  function fmt(metric, value) {
    // The rule of arena/figures.py, which every page, the CSV and the CLI use: toFixed rounds
    // halves away from zero on the exact value as it does; "—" when nothing was measured.
    if (value === null || value === undefined) return "—";
    return metric === "time" ? value.toFixed(1) : value.toFixed(4);
  }

  // The results drawn by the server (GET .../results.svg: completion's interval as a bar, the
  // four metrics per family beside the leaderboard's median), fetched once per score.
  const drawn = { key: null };
  async function loadResultsChart(s, token) {
    const key = s.metrics ? `${s.id}:${s.status}:${s.metrics.completion}` : null;
    if (key === drawn.key) return;
    drawn.key = key;
    $("results-chart").innerHTML = "";
    if (!key) return;
    const response = await fetch(`${API}/submissions/${s.id}/results.svg`,
      { headers: headers(token) });
    if (response.ok && drawn.key === key) $("results-chart").innerHTML = await response.text();
  }

  function escape(text) {
    const div = document.createElement("div");
    div.textContent = text;
    return div.innerHTML;
  }

  // Text of ours that names a command in backticks (`arena evaluate`): escaped, and each
  // backticked part shown as code instead of with literal backticks.
  function prose(text) {
    return escape(text).replace(/`([^`]+)`/g, "<code>$1</code>");
  }

  function duration(seconds) {
    if (seconds === null || seconds === undefined) return "";
    const s = Math.round(seconds);
    if (s < 60) return `${s} s`;
    if (s < 3600) return `${Math.floor(s / 60)} min ${s % 60} s`;
    return `${Math.floor(s / 3600)} h ${Math.round((s % 3600) / 60)} min`;
  }

  function renderPhase(s) {
    const p = s.phase_window;
    $("phase-name").textContent = s.phase;
    if (!p) return;
    $("phase-hidden").innerHTML = prose(p.hidden);
    $("phase-hidden").hidden = !p.hidden;
    const opens = p.starts_at ? `opened ${when(p.starts_at)} UTC` : "open from the start";
    const closes = p.ends_at
      ? `${p.state === "closed" ? "closed" : "closes"} ${when(p.ends_at)} UTC` : "never closes";
    const c = p.cpu_limits;
    const cpu = ` Agent CPU limits: ${c.step_s} s per act, ${c.episode_s} s per episode, ` +
      `${c.evaluation_s} s per evaluation.`;
    $("phase-dates").textContent = (p.state === "not yet open"
      ? `Phase ${p.name} opens ${when(p.starts_at)} UTC.`
      : `Phase ${p.name}: ${opens}, ${closes}.`) + cpu;
    // What a hidden phase withholds is said above; the empty expander would only repeat it.
    $("logs-box").hidden = Boolean(p.hidden);
  }

  function renderTimings(s) {
    const parts = [`submitted ${when(s.created_at)}`];
    if (s.queued_at) parts.push(`queued ${when(s.queued_at)}`);
    if (s.started_at) parts.push(`started ${when(s.started_at)}`);
    if (s.finished_at) parts.push(`finished ${when(s.finished_at)}`);
    if (s.duration_s !== null && s.duration_s !== undefined) {
      parts.push(`${s.finished_at ? "took" : "running for"} ${duration(s.duration_s)}`);
    }
    $("timings").textContent = `${parts.join(" · ")} (UTC)`;
  }

  function renderAgentCpu(s) {
    // The evaluation's CPU budget: past it, the remaining episodes are not run.
    const cpu = s.agent_cpu;
    $("agent-cpu").hidden = !cpu;
    if (!cpu) return;
    const share = (used) =>
      cpu.budget_s > 0 ? ` (${Math.round((100 * used) / cpu.budget_s)}%)` : "";
    // Several training seeds: each seed's model is its own evaluation with its own budget.
    $("agent-cpu").textContent = cpu.evaluations > 1
      ? `Agent CPU: ${duration(cpu.used_s)} used over the ${cpu.evaluations} seeds' ` +
        `evaluations, each with a budget of ${duration(cpu.budget_s)}; the most one used is ` +
        `${duration(cpu.most_used_s)}${share(cpu.most_used_s)}.`
      : `Agent CPU: ${duration(cpu.used_s)} used of this evaluation's budget of ` +
        `${duration(cpu.budget_s)}${share(cpu.used_s)}.`;
  }

  function renderStanding(s) {
    const st = s.standing;
    $("standing").hidden = !st;
    if (!st) return;
    const board = `the ${s.phase} leaderboard (${s.track})`;
    let text = st.rank === null ? `Your team is not ranked on ${board} yet.`
      : `Your team holds rank ${st.rank} of ${st.teams_ranked} on ${board}` +
        (st.ranked_submission_id === s.id ? " with this submission"
          : ` with submission ${st.ranked_submission_id}`) +
        // The rank range in the words of the leaderboard and the CLI (said by the server).
        `; ${st.statistics}.`;
    text += ` ${st.tries_left_today} of ${st.daily_quota} uploads left today in this phase.`;
    $("standing").textContent = text;
  }

  function progressText(s) {
    // An offline submission trains before it has anything to count.
    if (!s.progress.total) {
      if (s.status === "training") return "training: the evaluation starts when it has trained";
      if (s.status === "queued" || s.status === "received") return "queued: waiting for a worker";
      return s.status === "running" ? "starting the evaluation" : "";
    }
    // A hidden phase's run under way is told in quarters, with no time left (no clock of it).
    if (s.progress.unit === "quarters") return `${s.progress.done} / 4 quarters done`;
    const left = s.status === "running" ? timeLeft(s.progress) : "";
    // Several episodes per reactive scenario: the progress counts episodes, and says the cost.
    const unit = s.episodes_per_scenario > 1
      ? `episodes (${s.episodes_per_scenario} of each reactive scenario)` : "scenarios";
    // Several training seeds: every seed's model runs the suite, and the progress counts all.
    const seeds = s.progress.seeds > 1 ? ` over ${s.progress.seeds} training seeds` : "";
    return `${s.progress.done} / ${s.progress.total} ${unit}${seeds}${left ? ` · ${left}` : ""}`;
  }

  function renderManifest(manifest) {
    // The reproducibility manifest (docs/api.md): what the score depends on, by version or sha256.
    $("manifest-box").hidden = !manifest;
    if (!manifest) return;
    const env = manifest.environments.map((e) =>
      `arena ${e.arena}, Python ${e.python}, numpy ${e.numpy}, SUMO ${e.sumo}, ${e.sandbox}` +
      (e.agent_image ? `, image ${e.agent_image}` : "")).join("; ");
    const rows = [
      ["submission sha256", manifest.submission],
      ...(manifest.seed_models && manifest.seed_models.length
        ? manifest.seed_models.map((x) => [`trained model sha256, seed ${x.seed}`, x.model])
        : [["trained model sha256", manifest.model || "—"]]),
      ["suite", `${manifest.suite} (manifest sha256 ${manifest.suite_hash})`],
      ["scenarios", `${manifest.scenario_hashes.length}, seeds sha256 ${manifest.seeds_sha256}`],
      ["episodes per reactive scenario", String(manifest.episodes_per_scenario)],
      ["scoring profile", `${manifest.profile} v${manifest.profile_version}`],
      ["software", env || "—"],
      // What the agent imported in its sandbox, by version: a framework's local label names its
      // build (torch 2.13.0+cpu: the CPU build).
      ["agent's stack", manifest.environments.map((e) => Object.entries(e.agent_stack || {})
        .map(([name, version]) => `${name} ${version}`).join(", ")).filter(Boolean)
        .join("; ") || "—"],
    ];
    const list = $("manifest");
    list.replaceChildren();
    for (const [name, value] of rows) {
      const dt = document.createElement("dt");
      dt.textContent = name;
      const dd = document.createElement("dd");
      dd.textContent = value;
      list.append(dt, dd);
    }
  }

  function render(s, metrics) {
    $("submission").hidden = false;
    renderManifest(s.manifest);
    $("method").textContent = s.method_name;
    $("track").textContent = s.track;
    renderPhase(s);
    renderTimings(s);
    renderAgentCpu(s);
    renderStanding(s);
    $("status").textContent = s.status;
    $("status").className = `status-${s.status}`;
    $("status-reason").innerHTML = prose(s.status_reason || "");
    const pct = s.progress.total ? (100 * s.progress.done) / s.progress.total : 0;
    $("progress-bar").style.width = `${pct}%`;
    $("progress-text").textContent = progressText(s);
    $("cancel").hidden = !["received", "queued", "training", "running"].includes(s.status);
    renderTraining(s.training, s.status);
    for (const metric of metrics) {
      $(`metric-${metric}`).textContent = s.metrics ? fmt(metric, s.metrics[metric]) : "–";
    }
    const ci = s.completion_interval;
    $("interval-row").hidden = !(s.metrics && ci);
    $("completion-interval").textContent =
      s.metrics && ci ? `[${fmt("completion", ci.low)}, ${fmt("completion", ci.high)}]` : "";
    renderSeeds(s.metrics && s.seeds);
    const families = Object.keys(s.families).sort();
    $("families-box").hidden = families.length === 0;
    $("families").innerHTML = families.length ? `<table><thead><tr><th>family</th>` +
      `<th class="num">scenarios</th>${metrics.map((m) => `<th class="num">${m}</th>`).join("")}` +
      `</tr></thead><tbody>${families.map((f) => `<tr><td>${escape(f)}</td>` +
      `<td class="num">${s.families[f].scenarios}</td>` +
      metrics.map((m) => `<td class="num">${fmt(m, s.families[f][m])}</td>`).join("") +
      `</tr>`).join("")}</tbody></table>` : "";
    const failures = Object.entries(s.failure_reasons);
    // No heading over nothing: failures show once counted, "None." only when it has finished
    // having run episodes (not one that failed in training, before any could run).
    $("failures-box").hidden = failures.length === 0 &&
      !(FINISHED.includes(s.status) && s.progress.total > 0);
    // Over several training seeds the counts are summed over every seed's run, then each seed's.
    const seeds = s.seed_failure_reasons || [];
    $("failures-scope").textContent = seeds.length > 1
      ? `(episodes summed over the ${seeds.length} training seeds; each seed's below)` : "";
    $("failures").innerHTML = failures.length ? failureList(failures) +
      (seeds.length > 1 ? `<ul class="per-seed">${seeds.map((x) => `<li>seed ${x.seed}: ` +
        (Object.keys(x.failure_reasons).length
          ? failureList(Object.entries(x.failure_reasons)) : "none") + `</li>`).join("")}</ul>`
        : "")
      : `<p class="empty">None.</p>`;
  }

  function failureList(failures) {
    // family -> reason -> episodes, as a list.
    return `<ul>${failures.map(([family, reasons]) =>
      `<li><strong>${escape(family)}</strong>: ${Object.entries(reasons)
        .map(([r, n]) => `${escape(r)} × ${n}`).join(", ")}</li>`).join("")}</ul>`;
  }

  function renderSeeds(seeds) {
    // Scored over several training seeds: their spread, then each seed's completion.
    $("seeds-row").hidden = !seeds;
    // Seeds that trained byte-identical models: their spread would read as a certain 0.
    const spread = seeds && seeds.ignores_seed ? `${seeds.ignores_seed}; `
      : seeds ? `completion ${fmt("completion", seeds.completion_min)}–` +
        `${fmt("completion", seeds.completion_max)} (std ${fmt("completion", seeds.completion_std)}); `
      : "";
    $("seeds-text").textContent = seeds
      ? `${seeds.count}: ${spread}` +
        seeds.per_seed.map((x) => `seed ${x.seed} ${fmt("completion", x.completion)}`).join(", ")
      : "";
  }

  function renderTraining(t, status) {
    // Offline (Track 2) submissions train first; their training log is the team's to read.
    $("training-box").hidden = !t;
    if (!t) return;
    $("training-box").open = status === "training" || t.status === "failed";
    const when = t.status === "training" || t.status === "queued"
      ? `${t.status} · ${Math.round(t.elapsed_s)} s elapsed`
      : `${t.status} in ${Math.round(t.elapsed_s)} s`;
    const failure = t.failure ? ` · ${t.failure}: ${t.error}` : "";
    const model = t.model_sha256 ? ` · model sha256 ${t.model_sha256.slice(0, 12)}… ` +
      `(${t.model_size} bytes)` : "";
    // Each seed is a training job of its own: a job's number is no retry, a new seed set is.
    const which = t.seeds > 1
      ? `seed ${t.seed} of ${t.seeds}` + (t.seed_set > 1 ? ` (retraining ${t.seed_set - 1})` : "")
      : t.seed_set > 1 ? `retraining ${t.seed_set - 1}` : "training";
    $("training-text").textContent = `${which} · ${when}${failure}${model}`;
    $("training-log").textContent = t.log_tail || "(no output yet)";
  }

  // The curves each seed's train.py logs, drawn by the server: refreshed about every 10 s
  // while it trains, once more when it ends; a hidden phase's go to the organisers only.
  const curvesDrawn = { key: null };
  async function loadTrainingCurves(s, token) {
    const t = s.training;
    const shown = Boolean(t) && !(s.phase_window && s.phase_window.hidden);
    $("training-curves").hidden = !shown;
    if (!shown) return;
    const key = `${t.seed_set}:${t.status}:${Math.floor(t.elapsed_s / 10)}`;
    if (key === curvesDrawn.key) return;
    curvesDrawn.key = key;
    const response = await fetch(`${API}/submissions/${s.id}/training.svg`,
      { headers: headers(token) });
    if (response.ok) $("training-curves").innerHTML = await response.text();
  }

  async function loadLogs(id, token) {
    const response = await fetch(`${API}/submissions/${id}/logs`, { headers: headers(token) });
    if (response.status === 403) {  // a hidden phase: the agent's output goes to the organisers
      $("logs").innerHTML = `<p class="empty">${escape((await response.json()).detail)}</p>`;
      return;
    }
    if (!response.ok) return;
    const logs = await response.json();
    episodes(id, logs.scenarios);
    // Identical output (the same traceback in 128 scenarios) is shown once, with its count.
    const groups = new Map();
    for (const e of logs.scenarios.filter((x) => x.reason !== "reached_goal" || x.log_tail)) {
      const key = `${e.reason || e.status}\u0000${e.log_tail}`;
      if (!groups.has(key)) groups.set(key, { entry: e, labels: [] });
      groups.get(key).labels.push(e.label);
    }
    $("logs").innerHTML = [...groups.values()].map(({ entry, labels }) => {
      const shown = labels.slice(0, 6).map(escape).join(", ") +
        (labels.length > 6 ? ` and ${labels.length - 6} more` : "");
      const count = labels.length > 1 ? ` <span class="count">× ${labels.length}</span>` : "";
      return `<h3 class="log-group">${shown} · ${escape(entry.reason || entry.status)}${count}</h3>` +
        `<pre>${escape(entry.log_tail || "(no output)")}</pre>`;
    }).join("");
  }

  // One "watch" link per finished scenario, failures first (shown where the phase shows logs).
  function episodes(id, scenarios) {
    const order = (e) => (e.reason === "reached_goal" ? 1 : 0);
    const sorted = [...scenarios].sort((a, b) => order(a) - order(b));
    $("episodes-box").hidden = sorted.length === 0;
    $("episodes").innerHTML = sorted.map((e) =>
      `<li><a href="/submissions/${id}/replays/${encodeURIComponent(e.scenario_id)}">` +
      `${escape(e.label)}</a> <span class="note">${escape(e.reason || e.status)} · ` +
      `<code>${escape(e.scenario_id)}</code></span></li>`).join("");
  }

  // The replay page: the team's own episode needs the team token this tab holds; an
  // organiser's view of any episode the admin token (kept apart, never sent as a team's).
  function replayPage(url, tokenKind) {
    const root = $("replay");
    const key = tokenKind === "admin" ? ADMIN_TOKEN_KEY : TOKEN_KEY;
    let token = tokenKind ? sessionStorage.getItem(key) : null;
    const load = () => ArenaReplay.mount(root, { url, token });
    $("token-form").addEventListener("submit", (event) => {
      event.preventDefault();
      token = $("token").value.trim();
      sessionStorage.setItem(key, token);
      $("token-form").hidden = true;
      load();
    });
    if (tokenKind && !token) {
      root.innerHTML = "";
      $("token-form").hidden = false;
    } else {
      load();
    }
  }

  // Time left, from the scenarios finished since this page started watching (a rate measured
  // here, so it needs no clock agreement with the server).
  const watch = { since: null, done: 0 };
  function timeLeft(progress) {
    const now = Date.now();
    if (watch.since === null || progress.done < watch.done) {
      watch.since = now;
      watch.done = progress.done;
    }
    const finished = progress.done - watch.done;
    if (finished <= 0) return "estimating time left…";
    const seconds = ((progress.total - progress.done) * (now - watch.since)) / finished / 1000;
    if (seconds < 90) return "under 2 min left";
    if (seconds < 5400) return `about ${Math.round(seconds / 60)} min left`;
    return `about ${(seconds / 3600).toFixed(1)} h left`;
  }

  function submissionPage(id, metrics) {
    let token = sessionStorage.getItem(TOKEN_KEY);
    const finished = FINISHED;
    async function poll() {
      const response = await fetch(`${API}/submissions/${id}`, { headers: headers(token) });
      if (!response.ok) {
        $("page-error").textContent = await errorText(response);
        $("page-error").hidden = false;
        $("token-form").hidden = false;
        return;
      }
      $("page-error").hidden = true;
      $("token-form").hidden = true;
      const s = await response.json();
      render(s, metrics);
      loadResultsChart(s, token);
      loadTrainingCurves(s, token);
      // A hidden phase's agent output goes to the organisers only: not even asked for.
      if (finished.includes(s.status) && !(s.phase_window && s.phase_window.hidden)) {
        loadLogs(id, token);
      } else {
        setTimeout(poll, 2000);
      }
    }
    $("token-form").addEventListener("submit", (event) => {
      event.preventDefault();
      token = $("token").value.trim();
      sessionStorage.setItem(TOKEN_KEY, token);
      poll();
    });
    $("cancel").addEventListener("click", async () => {
      const response = await fetch(`${API}/submissions/${id}/cancel`, {
        method: "POST", headers: headers(token),
      });
      if (!response.ok) {
        $("page-error").textContent = await errorText(response);
        $("page-error").hidden = false;
      }
      poll();
    });
    if (token) poll(); else $("token-form").hidden = false;
  }

  function when(iso) {
    // "2026-11-23 13:05" in UTC, like the leaderboard.
    return iso.replace("T", " ").slice(0, 16);
  }

  async function download(id, token, link) {
    // The zip needs the Authorization header, so it is fetched here and handed over as a blob.
    const response = await fetch(`${API}/submissions/${id}/download`, { headers: headers(token) });
    if (!response.ok) {
      $("page-error").textContent = await errorText(response);
      $("page-error").hidden = false;
      return;
    }
    const url = URL.createObjectURL(await response.blob());
    const a = document.createElement("a");
    a.href = url;
    a.download = `submission-${id}.zip`;
    document.body.appendChild(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(url), 10000);
    link.dataset.downloaded = "1";
  }

  function mySubmissions(metrics) {
    let token = sessionStorage.getItem(TOKEN_KEY);
    async function load() {
      const response = await fetch(`${API}/submissions`, { headers: headers(token) });
      if (!response.ok) {
        $("page-error").textContent = await errorText(response);
        $("page-error").hidden = false;
        $("token-form").hidden = false;
        return;
      }
      $("page-error").hidden = true;
      $("token-form").hidden = true;
      $("nav-mine").hidden = false;
      const rows = await response.json();
      $("none").hidden = rows.length > 0;
      $("mine").hidden = rows.length === 0;
      if (rows.length) {
        $("team").textContent = `Team ${rows[0].team}: ${rows.length} submission(s), newest first.`;
        $("team").hidden = false;
      }
      $("mine").querySelector("tbody").innerHTML = rows.map((s) => `<tr data-id="${s.id}">` +
        `<td><a href="/submissions/${s.id}">${s.id}</a></td>` +
        `<td class="wrap">${escape(s.method_name)}</td><td>${escape(s.phase)}</td>` +
        `<td>${escape(s.track)}</td>` +
        `<td class="status-${s.status}">${escape(s.status)}` +
        (["queued", "running"].includes(s.status) && s.progress.total
          ? ` ${s.progress.done}/${s.progress.total}` : "") + `</td>` +
        metrics.map((m) => `<td class="num">${s.metrics ? fmt(m, s.metrics[m]) : "–"}</td>`)
          .join("") +
        `<td>${when(s.created_at)}</td><td class="num">${duration(s.duration_s)}</td>` +
        `<td><a href="#" class="download" data-id="${s.id}">zip</a></td></tr>`).join("");
      for (const link of document.querySelectorAll("a.download")) {
        link.addEventListener("click", (event) => {
          event.preventDefault();
          download(link.dataset.id, token, link);
        });
      }
    }
    $("token-form").addEventListener("submit", (event) => {
      event.preventDefault();
      token = $("token").value.trim();
      sessionStorage.setItem(TOKEN_KEY, token);
      load();
    });
    if (token) load(); else $("token-form").hidden = false;
  }

  return { submitForm, submissionPage, mySubmissions, replayPage };
})();
