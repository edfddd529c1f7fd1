// Episode replay viewer: the map, every vehicle step by step, play/pause/scrub, and the followed
// agent's speed and events on a timeline. Reads the replay JSON of evaluator/viewer/model.py,
// fetched from the API or inlined in a file written by `arena replay --format html`.
// Nothing is loaded from elsewhere. The state (`element.replay`) is open so tests can read it.
const ArenaReplay = (() => {
  const SPEEDS = [0.25, 0.5, 1, 2, 4];
  const FOLLOW_VIEW_M = 110;  // width of road shown around the followed vehicle
  const MIN_FOLLOW_SCALE = 6;  // [px/m]: on a phone less road, cars still big enough to see
  const MIN_SCALE = 0.2, MAX_SCALE = 40;  // [px/m]

  function el(tag, attrs = {}, text = "") {
    const node = document.createElement(tag);
    for (const [key, value] of Object.entries(attrs)) node.setAttribute(key, value);
    if (text) node.textContent = text;
    return node;
  }

  function build(root) {
    root.classList.add("replay");
    root.innerHTML = "";
    const ui = {
      view: el("canvas", { class: "replay-view", "aria-label": "episode replay" }),
      play: el("button", { type: "button", class: "replay-play" }, "Play"),
      scrub: el("input", { type: "range", min: "0", value: "0", step: "1", class: "replay-scrub", "aria-label": "step" }),
      counter: el("span", { class: "replay-counter", "aria-live": "off" }),
      speed: el("select", { class: "replay-speed", "aria-label": "playback speed" }),
      follow: el("select", { class: "replay-follow", "aria-label": "camera" }),
      zoomIn: el("button", { type: "button", class: "replay-zoom", "aria-label": "zoom in" }, "+"),
      zoomOut: el("button", { type: "button", class: "replay-zoom", "aria-label": "zoom out" }, "−"),
      timeline: el("canvas", { class: "replay-timeline", "aria-label": "speed and events over the episode" }),
      events: el("ul", { class: "replay-events" }),
      status: el("p", { class: "replay-status" }),
    };
    for (const s of SPEEDS) ui.speed.append(el("option", { value: String(s) }, `${s}×`));
    ui.speed.value = "1";
    const bar = el("div", { class: "replay-bar" });
    bar.append(ui.play, ui.scrub, ui.counter);
    const tools = el("div", { class: "replay-tools" });
    const speedLabel = el("label", {}, "speed ");
    speedLabel.append(ui.speed);
    const followLabel = el("label", {}, "camera ");
    followLabel.append(ui.follow);
    const zoom = el("span", { class: "replay-zoom-group" });
    zoom.append(ui.zoomOut, ui.zoomIn);
    tools.append(followLabel, speedLabel, zoom);
    root.append(ui.view, bar, tools, ui.timeline, ui.events, ui.status);
    return ui;
  }

  class Viewer {
    constructor(root, data) {
      this.root = root;
      this.data = data;
      this.ui = build(root);
      this.frame = 0;
      this.playing = false;
      this.rate = 1;
      this.followed = 0;  // index into data.agents, or -1: the whole map
      this.scale = null;  // [px/m], set on the first layout
      this.userZoomed = false;
      this.drawn = [];
      const labels = [];
      this.wire();
      this.resize();
      new ResizeObserver(() => this.resize()).observe(root);
      this.seek(0);
    }

    wire() {
      const { ui, data } = this;
      ui.scrub.max = String(data.frames - 1);
      data.agents.forEach((a, i) => ui.follow.append(el("option", { value: String(i) }, `follow ${a.id}`)));
      ui.follow.append(el("option", { value: "-1" }, "whole map"));
      ui.play.addEventListener("click", () => (this.playing ? this.pause() : this.play()));
      ui.scrub.addEventListener("input", () => { this.pause(); this.seek(Number(ui.scrub.value)); });
      ui.speed.addEventListener("change", () => { this.rate = Number(ui.speed.value); });
      ui.follow.addEventListener("change", () => {
        this.followed = Number(ui.follow.value);
        this.userZoomed = false;
        this.scale = this.defaultScale();
        this.render();
      });
      ui.zoomIn.addEventListener("click", () => this.zoom(1.5));
      ui.zoomOut.addEventListener("click", () => this.zoom(1 / 1.5));
      ui.view.addEventListener("wheel", (e) => { e.preventDefault(); this.zoom(e.deltaY < 0 ? 1.2 : 1 / 1.2); }, { passive: false });
      const scrubTimeline = (e) => {
        const box = ui.timeline.getBoundingClientRect();
        const f = Math.round(((e.clientX - box.left - this.plotLeft) / (box.width - this.plotLeft - 8)) * (data.frames - 1));
        this.pause();
        this.seek(f);
      };
      ui.timeline.addEventListener("pointerdown", (e) => {
        scrubTimeline(e);
        const move = (m) => scrubTimeline(m);
        ui.timeline.addEventListener("pointermove", move);
        window.addEventListener("pointerup", () => ui.timeline.removeEventListener("pointermove", move), { once: true });
      });
      this.root.tabIndex = 0;
      this.root.addEventListener("keydown", (e) => {
        if (e.target.tagName === "SELECT") return;
        if (e.key === " ") { e.preventDefault(); this.playing ? this.pause() : this.play(); }
        if (e.key === "ArrowRight") { e.preventDefault(); this.pause(); this.seek(this.frame + 1); }
        if (e.key === "ArrowLeft") { e.preventDefault(); this.pause(); this.seek(this.frame - 1); }
      });
      this.listEvents();
    }

    listEvents() {
      const { ui, data } = this;
      ui.events.innerHTML = "";
      data.agents.forEach((agent) => {
        for (const [frame, name] of agent.events) {
          const item = el("li");
          const jump = el("button", { type: "button", class: "replay-event" }, `${agent.id}: ${name.replaceAll("_", " ")} @ step ${data.first_step + frame}`);
          jump.style.setProperty("--event", data.style.events[name] || "#333");
          jump.addEventListener("click", () => { this.pause(); this.seek(frame); });
          item.append(jump);
          ui.events.append(item);
        }
      });
      const end = data.agents.map((a) => `${a.id}: ${a.done_reason.replaceAll("_", " ")} at step ${a.done_step}`).join(" · ");
      ui.status.textContent = `${data.scenario_id} · ${end}` + (data.map ? "" : " · map not available");
    }

    play() {
      if (this.frame >= this.data.frames - 1) this.seek(0);
      this.playing = true;
      this.ui.play.textContent = "Pause";
      let last = performance.now();
      let carry = 0;
      const tick = (now) => {
        if (!this.playing) return;
        carry += ((now - last) / 1000) * this.rate / this.data.dt;
        last = now;
        const steps = Math.floor(carry);
        if (steps > 0) {
          carry -= steps;
          this.seek(Math.min(this.frame + steps, this.data.frames - 1));
          if (this.frame >= this.data.frames - 1) { this.pause(); return; }
        }
        requestAnimationFrame(tick);
      };
      requestAnimationFrame(tick);
    }

    pause() {
      this.playing = false;
      this.ui.play.textContent = "Play";
    }

    seek(frame) {
      this.frame = Math.max(0, Math.min(this.data.frames - 1, Math.round(frame)));
      this.ui.scrub.value = String(this.frame);
      this.root.dataset.frame = String(this.frame);
      this.render();
    }

    zoom(factor) {
      this.scale = Math.max(MIN_SCALE, Math.min(MAX_SCALE, this.scale * factor));
      this.userZoomed = true;
      this.render();
    }

    resize() {
      const { view, timeline } = this.ui;
      const dpr = window.devicePixelRatio || 1;
      const width = view.clientWidth || 600;
      const height = Math.round(Math.min(Math.max(width * 0.6, 260), 560));
      view.style.height = `${height}px`;
      view.width = Math.round(width * dpr);
      view.height = Math.round(height * dpr);
      timeline.width = Math.round((timeline.clientWidth || width) * dpr);
      timeline.height = Math.round(120 * dpr);
      this.dpr = dpr;
      this.width = width;
      this.height = height;
      if (this.scale === null || !this.userZoomed) this.scale = this.defaultScale();
      this.render();
    }

    defaultScale() {
      if (this.followed >= 0) return Math.max(this.width / FOLLOW_VIEW_M, MIN_FOLLOW_SCALE);
      const [x0, y0, x1, y1] = this.data.bounds;
      return Math.min(this.width / (x1 - x0), this.height / (y1 - y0));
    }

    pose(v, frame) {
      const vehicle = this.data.vehicles[v];
      const i = frame - vehicle.start;
      if (i < 0 || i >= vehicle.x.length || vehicle.x[i] === null) return null;
      return { x: vehicle.x[i], y: vehicle.y[i], heading: vehicle.heading[i] };
    }

    centre() {
      const [x0, y0, x1, y1] = this.data.bounds;
      if (this.followed >= 0) {
        // Before it starts and after it ends, the followed vehicle's nearest known pose.
        const vehicle = this.data.vehicles[this.data.agents[this.followed].vehicle];
        const last = vehicle.x.length - 1;
        for (let i = Math.min(this.frame - vehicle.start, last); i >= 0; i--) {
          if (vehicle.x[i] !== null) return { x: vehicle.x[i], y: vehicle.y[i] };
        }
        const first = vehicle.x.findIndex((v) => v !== null);
        if (first >= 0) return { x: vehicle.x[first], y: vehicle.y[first] };
      }
      return { x: (x0 + x1) / 2, y: (y0 + y1) / 2 };
    }

    render() {
      if (!this.width) return;
      const { data } = this;
      const ctx = this.ui.view.getContext("2d");
      const s = this.scale;
      const c = this.centre();
      const toPx = (x, y) => [this.width / 2 + (x - c.x) * s, this.height / 2 - (y - c.y) * s];
      ctx.setTransform(this.dpr, 0, 0, this.dpr, 0, 0);
      ctx.fillStyle = data.style.background;
      ctx.fillRect(0, 0, this.width, this.height);
      if (data.map) this.drawMap(ctx, toPx, s);
      const goalLabels = [];
      this.drawGoals(ctx, toPx, s, goalLabels);
      this.drawTrail(ctx, toPx);
      this.drawn = [];
      const labels = [], boxes = [];
      data.vehicles.forEach((vehicle, v) => {
        const p = this.pose(v, this.frame);
        if (!p) return;
        this.drawn.push({ id: vehicle.id, kind: vehicle.kind, x: p.x, y: p.y, heading: p.heading });
        this.drawVehicle(ctx, toPx, s, vehicle, p);
        const [px, py] = toPx(p.x, p.y);
        const r = Math.max(vehicle.length * s, 3) / 2;
        boxes.push({ x0: px - r, x1: px + r, y0: py - r, y1: py + r });
        if (vehicle.kind !== "traffic") labels.push([vehicle.id, px, py, vehicle.width * s]);
      });
      this.drawLabels(ctx, [...labels, ...goalLabels], boxes);
      this.drawTimeline();
      const agent = data.agents[Math.max(this.followed, 0)];
      const speed = agent.speed[this.frame];
      const step = data.first_step + this.frame;
      this.ui.counter.textContent = `step ${step} / ${data.first_step + data.frames - 1} · ` +
        `${(step * data.dt).toFixed(1)} s · ${agent.id} ${speed === null ? "–" : speed.toFixed(1)} m/s`;
    }

    // Labels last, in screen pixels at a fixed size (they never scale with the road), each moved
    // up or down out of the way of the labels placed before it and of every vehicle drawn
    // (`boxes`), with a leader line when moved.
    drawLabels(ctx, labels, boxes) {
      ctx.font = "600 12px system-ui, sans-serif";
      ctx.textAlign = "center";
      const placed = [];
      const hits = (r, q) => r.x0 < q.x1 && q.x0 < r.x1 && r.y0 < q.y1 && q.y0 < r.y1;
      const offView = (r) => r.y0 < 0 || r.y1 > this.height;
      const overlaps = (r) => offView(r) || placed.some((q) => hits(r, q)) || boxes.some((q) => hits(r, q));
      for (const [text, px, py, w] of labels) {
        const half = ctx.measureText(text).width / 2 + 2;
        const spots = [...Array(12).keys()].map((k) => {
          const lift = (Math.floor(k / 2) * 15) + w + 8;
          const y = k % 2 === 0 ? py - lift : py + lift + 10;
          return { x0: px - half, x1: px + half, y0: y - 11, y1: y + 3, y };
        });
        // Nowhere clear (a crowd of vehicles): right above the anchor.
        const box = spots.find((spot) => !overlaps(spot)) || spots[0];
        placed.push(box);
        if (Math.abs(box.y - py) > w + 20) {
          ctx.strokeStyle = "rgba(17,17,17,.6)";
          ctx.lineWidth = 1;
          ctx.beginPath(); ctx.moveTo(px, py); ctx.lineTo(px, box.y < py ? box.y1 : box.y0); ctx.stroke();
        }
        ctx.lineWidth = 3;
        ctx.strokeStyle = "rgba(255,255,255,.9)";
        ctx.strokeText(text, px, box.y);
        ctx.fillStyle = "#111";
        ctx.fillText(text, px, box.y);
      }
      this.labels = placed;
      this.vehicleBoxes = boxes;
    }

    drawMap(ctx, toPx, s) {
      const { map, style } = this.data;
      const fill = (shapes, colour) => {
        ctx.fillStyle = colour;
        for (const shape of shapes) {
          ctx.beginPath();
          shape.forEach(([x, y], i) => (i ? ctx.lineTo(...toPx(x, y)) : ctx.moveTo(...toPx(x, y))));
          ctx.closePath();
          ctx.fill();
        }
      };
      const stroke = (lines, colour, width, dash) => {
        ctx.strokeStyle = colour;
        ctx.lineWidth = Math.max(width * s, 1);
        ctx.setLineDash(dash);
        for (const line of lines) {
          ctx.beginPath();
          line.forEach(([x, y], i) => (i ? ctx.lineTo(...toPx(x, y)) : ctx.moveTo(...toPx(x, y))));
          ctx.stroke();
        }
        ctx.setLineDash([]);
      };
      fill(map.junctions, style.junction);
      fill(map.lanes, style.road);
      fill(map.shoulders, style.shoulder);
      stroke(map.dashed, style.marking, 0.15, [3 * s, 3 * s]);
      stroke(map.solid, style.marking, 0.15, []);
      stroke(map.stop_lines, style.stop_line, 0.5, []);
    }

    // Goal circles; their labels (several agents only) go with the vehicles' into `labels`.
    drawGoals(ctx, toPx, s, labels) {
      const { style } = this.data;
      for (const agent of this.data.agents) {
        const [gx, gy, r] = agent.goal;
        const [px, py] = toPx(gx, gy);
        ctx.beginPath();
        ctx.arc(px, py, Math.max(r * s, 4), 0, 2 * Math.PI);
        ctx.fillStyle = style.goal + "88";
        ctx.fill();
        ctx.strokeStyle = style.goal;
        ctx.lineWidth = 1.5;
        ctx.stroke();
        if (this.data.agents.length > 1) labels.push([`goal ${agent.id}`, px, py, Math.max(r * s, 4)]);
      }
    }

    drawTrail(ctx, toPx) {
      const { style } = this.data;
      for (const agent of this.data.agents) {
        const vehicle = this.data.vehicles[agent.vehicle];
        ctx.beginPath();
        let started = false;
        for (let i = 0; i < vehicle.x.length && vehicle.start + i <= this.frame; i++) {
          if (vehicle.x[i] === null) continue;
          const [px, py] = toPx(vehicle.x[i], vehicle.y[i]);
          started ? ctx.lineTo(px, py) : ctx.moveTo(px, py);
          started = true;
        }
        ctx.strokeStyle = style[vehicle.kind] + "aa";
        ctx.lineWidth = 2;
        ctx.stroke();
      }
    }

    drawVehicle(ctx, toPx, s, vehicle, p) {
      const [px, py] = toPx(p.x, p.y);
      const l = Math.max(vehicle.length * s, 3), w = Math.max(vehicle.width * s, 2);
      ctx.save();
      ctx.translate(px, py);
      ctx.rotate(-p.heading);
      ctx.fillStyle = this.data.style[vehicle.kind];
      ctx.strokeStyle = "#222";
      ctx.lineWidth = 1;
      ctx.fillRect(-l / 2, -w / 2, l, w);
      ctx.strokeRect(-l / 2, -w / 2, l, w);
      ctx.fillStyle = "rgba(34,34,34,.6)";  // the nose, so the heading shows
      ctx.fillRect(0.3 * l, -w / 2, 0.2 * l, w);
      ctx.restore();
    }

    drawTimeline() {
      const { data } = this;
      const canvas = this.ui.timeline;
      const ctx = canvas.getContext("2d");
      const width = canvas.width / this.dpr, height = canvas.height / this.dpr;
      ctx.setTransform(this.dpr, 0, 0, this.dpr, 0, 0);
      ctx.clearRect(0, 0, width, height);
      const agent = data.agents[Math.max(this.followed, 0)];
      const values = [...agent.speed, ...agent.speed_limit].filter((v) => v !== null);
      const top = Math.max(1, ...values) * 1.1;
      const left = (this.plotLeft = 40), right = width - 8, y0 = height - 18, y1 = 16;
      const fx = (f) => left + (f / Math.max(data.frames - 1, 1)) * (right - left);
      const fy = (v) => y0 - (v / top) * (y0 - y1);
      ctx.font = "11px system-ui, sans-serif";
      ctx.fillStyle = "#667085";
      ctx.textAlign = "right";
      ctx.fillText(`${top.toFixed(0)} m/s`, left - 4, y1 + 4);
      ctx.fillText("0", left - 4, y0);
      ctx.textAlign = "left";
      ctx.fillText(`step ${data.first_step}`, left, height - 4);
      ctx.textAlign = "right";
      ctx.fillText(`${data.first_step + data.frames - 1}`, right, height - 4);
      ctx.strokeStyle = "#e4e7ec";
      ctx.beginPath(); ctx.moveTo(left, y0); ctx.lineTo(right, y0); ctx.stroke();
      const line = (series, colour, dash) => {
        ctx.strokeStyle = colour;
        ctx.lineWidth = 1.5;
        ctx.setLineDash(dash);
        ctx.beginPath();
        let pen = false;
        series.forEach((v, f) => {
          if (v === null) { pen = false; return; }
          pen ? ctx.lineTo(fx(f), fy(v)) : ctx.moveTo(fx(f), fy(v));
          pen = true;
        });
        ctx.stroke();
        ctx.setLineDash([]);
      };
      line(agent.speed_limit, "#98a2b3", [4, 3]);
      line(agent.speed, data.style[data.vehicles[agent.vehicle].kind], []);
      for (const [frame, name] of agent.events) {
        ctx.fillStyle = data.style.events[name] || "#333";
        const x = fx(frame);
        ctx.beginPath(); ctx.moveTo(x - 5, 2); ctx.lineTo(x + 5, 2); ctx.lineTo(x, 11); ctx.fill();
        ctx.fillRect(x - 0.5, 11, 1, y0 - 11);
      }
      ctx.strokeStyle = "#1d2330";
      ctx.lineWidth = 1.5;
      ctx.beginPath(); ctx.moveTo(fx(this.frame), y1 - 6); ctx.lineTo(fx(this.frame), y0); ctx.stroke();
    }
  }

  function show(root, message) {
    root.innerHTML = "";
    root.append(el("pre", { class: "error", role: "alert" }, message));
  }

  // Draw `data` (a replay object) or fetch it from `url` (with `token` as a bearer token).
  async function mount(root, { data = null, url = null, token = null } = {}) {
    if (!data) {
      const response = await fetch(url, { headers: token ? { Authorization: `Bearer ${token}` } : {} });
      if (!response.ok) {
        let detail = `${response.status} ${response.statusText}`;
        try { const body = await response.json(); if (typeof body.detail === "string") detail = body.detail; } catch { /* not JSON */ }
        show(root, `No replay: ${detail}`);
        return null;
      }
      data = await response.json();
    }
    root.replay = new Viewer(root, data);
    return root.replay;
  }

  return { mount };
})();
