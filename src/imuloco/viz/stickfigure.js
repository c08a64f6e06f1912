// imuloco stick figures on a 2-D canvas, shared by the offline viewer (viz/viewer.html) and the
// live page (live/live.html); Python inlines this text into both pages (imuloco.viz.html), so
// nothing is fetched and the viewer file still works offline.
// Hand-written orthographic projection: a stick figure needs no WebGL library.
// World: metres, Y up. Camera: an orbit about +Y at `azimuth`, tilted down by `elevation`.
const StickFigure = (() => {
  "use strict";
  const SIDE_COLORS = { left: "#1f77b4", right: "#d62728", center: "#444444" };
  // A frame the method flags as unreliable: the figure is drawn over a halo of this colour,
  // with this label (imuloco.viz.html.UNRELIABLE_LABEL).
  const UNRELIABLE_COLOR = "#ffb000";
  const UNRELIABLE_LABEL = "unreliable: the model does not know this motion";

  // The line a page shows for a frame's confidence: errorM the predicted rms joint position
  // error in metres (null or NaN: none), unreliable a bool (null: not flagged by the method).
  function confidenceText(errorM, unreliable) {
    const parts = [];
    if (errorM !== null && errorM !== undefined && Number.isFinite(errorM)) {
      parts.push(`predicted error ${(errorM * 100).toFixed(1)} cm`);
    }
    if (unreliable) parts.push(UNRELIABLE_LABEL);
    return parts.join(" \u00b7 ");
  }

  // The camera's screen axes in world coordinates: {right, up}, unit 3-vectors.
  function cameraAxes(azimuth, elevation) {
    const a = azimuth, e = elevation;
    const right = [Math.cos(a), 0, -Math.sin(a)], back = [Math.sin(a), 0, Math.cos(a)];
    return { right, up: [-Math.sin(e) * back[0], Math.cos(e), -Math.sin(e) * back[2]] };
  }

  // (x, y, z) world metres -> [x, y] canvas pixels. view: {azimuth, elevation, zoom,
  // center: [x, y, z] (only x and z are used), floor and height (metres)}; panel: {x, width,
  // height} pixels. The center stands at the panel's middle, on the floor, 82% of the way down;
  // the figure's height fills 1 / 1.5 of the panel at zoom 1.
  function projector(view, panel) {
    const cam = cameraAxes(view.azimuth, view.elevation);
    const scale = view.zoom * panel.height / (view.height * 1.5);
    const c = view.center, x0 = panel.x + panel.width / 2, y0 = panel.height * 0.82;
    return (x, y, z) => {
      const d = [x - c[0], y - view.floor, z - c[2]];
      return [x0 + (d[0] * cam.right[0] + d[2] * cam.right[2]) * scale,
              y0 - (d[0] * cam.up[0] + d[1] * cam.up[1] + d[2] * cam.up[2]) * scale];
    };
  }

  // Fit the canvas's pixel size to its on-screen size; returns the device pixel ratio.
  function fitCanvas(canvas) {
    const dpr = window.devicePixelRatio || 1;
    const cw = Math.round(canvas.clientWidth * dpr), ch = Math.round(canvas.clientHeight * dpr);
    if (canvas.width !== cw || canvas.height !== ch) { canvas.width = cw; canvas.height = ch; }
    return dpr;
  }

  // Floor grid lines every `step` metres, `half` metres around center [x, y, z].
  function drawGrid(ctx, proj, center, floor, step = 0.5, half = 3) {
    const [cx, , cz] = center;
    ctx.strokeStyle = "#dddddd";
    ctx.lineWidth = 1;
    ctx.beginPath();
    for (let v = -half; v <= half; v += step) {
      const gx = Math.round(cx / step) * step + v, gz = Math.round(cz / step) * step + v;
      let a = proj(gx, floor, cz - half), b = proj(gx, floor, cz + half);
      ctx.moveTo(a[0], a[1]); ctx.lineTo(b[0], b[1]);
      a = proj(cx - half, floor, gz); b = proj(cx + half, floor, gz);
      ctx.moveTo(a[0], a[1]); ctx.lineTo(b[0], b[1]);
    }
    ctx.stroke();
  }

  // Bones from each joint's parent, coloured by side (sides[j]: left, right or center), and a
  // dot on the head joint. pts: [[x, y], ...] pixels per joint; parents[0] is the root's.
  // halo: a colour drawn wide under the bones (UNRELIABLE_COLOR marks an unreliable frame).
  function drawFigure(ctx, pts, parents, sides, head, dpr, halo = null) {
    ctx.lineCap = "round";
    if (halo) {
      ctx.lineWidth = 11 * dpr;
      ctx.strokeStyle = halo;
      ctx.beginPath();
      for (let j = 1; j < pts.length; j++) {
        ctx.moveTo(pts[parents[j]][0], pts[parents[j]][1]);
        ctx.lineTo(pts[j][0], pts[j][1]);
      }
      ctx.stroke();
    }
    ctx.lineWidth = 3 * dpr;
    for (let j = 1; j < pts.length; j++) {
      const p = parents[j];
      ctx.strokeStyle = SIDE_COLORS[sides[j]];
      ctx.beginPath();
      ctx.moveTo(pts[p][0], pts[p][1]);
      ctx.lineTo(pts[j][0], pts[j][1]);
      ctx.stroke();
    }
    ctx.fillStyle = SIDE_COLORS.center;
    ctx.beginPath();
    ctx.arc(pts[head][0], pts[head][1], 5 * dpr, 0, 2 * Math.PI);
    ctx.fill();
  }

  // Orbit by dragging (mouse, pen or one finger), zoom by wheel or two fingers: updates
  // view.azimuth, view.elevation and view.zoom, then calls onChange(). The canvas has the class
  // "dragging" while a pointer is down.
  function orbitControls(canvas, view, onChange) {
    const pointers = new Map();
    let pinch = null;
    const zoomBy = f => { view.zoom = Math.max(0.2, Math.min(5, view.zoom * f)); };
    canvas.addEventListener("pointerdown", e => {
      canvas.setPointerCapture(e.pointerId);
      pointers.set(e.pointerId, [e.clientX, e.clientY]);
      canvas.classList.add("dragging");
    });
    canvas.addEventListener("pointermove", e => {
      if (!pointers.has(e.pointerId)) return;
      const [x0, y0] = pointers.get(e.pointerId);
      pointers.set(e.pointerId, [e.clientX, e.clientY]);
      if (pointers.size === 2) {
        const [a, b] = [...pointers.values()];
        const d = Math.hypot(a[0] - b[0], a[1] - b[1]);
        if (pinch) zoomBy(d / pinch);
        pinch = d;
      } else {
        view.azimuth -= (e.clientX - x0) * 0.01;
        view.elevation = Math.max(-0.2, Math.min(1.5, view.elevation + (e.clientY - y0) * 0.01));
      }
      onChange();
    });
    const release = e => {
      pointers.delete(e.pointerId);
      pinch = null;
      if (pointers.size === 0) canvas.classList.remove("dragging");
    };
    canvas.addEventListener("pointerup", release);
    canvas.addEventListener("pointercancel", release);
    canvas.addEventListener("wheel", e => {
      e.preventDefault();
      zoomBy(Math.exp(-e.deltaY * 0.001));
      onChange();
    }, { passive: false });
  }

  return { SIDE_COLORS, UNRELIABLE_COLOR, UNRELIABLE_LABEL, confidenceText, cameraAxes,
           projector, fitCanvas, drawGrid, drawFigure, orbitControls };
})();
