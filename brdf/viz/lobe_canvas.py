"""The explorer's 3-D lobe view: lobe meshes drawn in the browser on a 2-D canvas, turned by
dragging and zoomed by the mouse wheel there, with no round trip to the server.

A Panel ``JSComponent``: the server sends each lobe's points (float32, base64) and the
mesh's triangles once; the page projects them, sorts the triangles far to near (the painter's
algorithm) and fills them flat-shaded in the material's colour. Panel's VTK pane (vtk.js) was
measured first and took 180 to 900 ms per update in headless chromium on two busy cores: it
synchronises the whole scene over several round trips and renders through software WebGL; this
view redraws in a few milliseconds and needs no WebGL.

Dragging the incident direction's arrow (its orange tip, or anywhere with Shift held) moves the
incident direction instead of turning the view: the page turns the pointer into a direction on
the sphere of the arrow's length (the upper hemisphere's point under it), draws the arrow there
at once and sends ``drag = [theta_i, phi_i, final, serial]`` (degrees) to the server, at most
every :data:`DRAG_EVERY_MS` while the pointer moves and once more, ``final``, when it is let go.
"""

import numpy as np

__all__ = ["lobe_canvas_class", "lobe_entry", "ARROW", "DRAG_EVERY_MS"]

#: Length of the incident direction's arrow (and the normal's), in lobe radii.
ARROW = 1.2
#: Milliseconds between two incidence updates sent while the arrow is dragged: the server's
#: draft update takes 15-60 ms on a loaded machine, so faster would only queue them.
DRAG_EVERY_MS = 50

_ESM = r"""
function rotate(p, yaw, pitch) {
  // turn about the normal z by yaw, then tilt about the screen's x axis by pitch
  const cy = Math.cos(yaw), sy = Math.sin(yaw), cp = Math.cos(pitch), sp = Math.sin(pitch);
  const x = cy * p[0] - sy * p[1], y = sy * p[0] + cy * p[1], z = p[2];
  return [x, cp * y - sp * z, sp * y + cp * z];   // screen x, depth (larger: farther), up
}

function unrotate(r, yaw, pitch) {
  // the inverse of rotate: screen x, depth, up back to the model's x, y, z
  const cy = Math.cos(yaw), sy = Math.sin(yaw), cp = Math.cos(pitch), sp = Math.sin(pitch);
  const y = cp * r[1] + sp * r[2], z = -sp * r[1] + cp * r[2];
  return [cy * r[0] + sy * y, -sy * r[0] + cy * y, z];
}

export function render({ model, el }) {
  const canvas = document.createElement("canvas");
  canvas.width = model.size; canvas.height = model.size;
  canvas.style.cursor = "grab";
  canvas.className = "brdf-lobe";
  const ctx = canvas.getContext("2d");
  let dragging = null;

  function project(p, scale) {
    // screen x and y, depth, and the turned point (for normals, in the model's units)
    const r = rotate(p, model.yaw, model.pitch);
    return [model.size / 2 + scale * r[0], model.size * 0.62 - scale * r[2], r[1], r];
  }

  function draw() {
    const t0 = performance.now();
    const n = model.size, scale = 0.42 * n * model.zoom;
    ctx.fillStyle = "#ffffff"; ctx.fillRect(0, 0, n, n);
    // the surface: a disc of radius 1.1 in the plane z = 0
    ctx.beginPath();
    for (let k = 0; k <= 64; k++) {
      const a = 2 * Math.PI * k / 64;
      const q = project([1.1 * Math.cos(a), 1.1 * Math.sin(a), 0], scale);
      if (k === 0) ctx.moveTo(q[0], q[1]); else ctx.lineTo(q[0], q[1]);
    }
    ctx.fillStyle = "rgba(200, 200, 200, 0.5)"; ctx.fill();
    const tris = model.triangles, faces = [];
    for (const lobe of model.lobes) {
      // float32 points, base64: far cheaper to send and to read than a JSON list
      const bytes = Uint8Array.from(atob(lobe.points), ch => ch.charCodeAt(0));
      const pts = new Float32Array(bytes.buffer), m = pts.length / 3, proj = new Array(m);
      for (let i = 0; i < m; i++) proj[i] = project([pts[3*i], pts[3*i+1], pts[3*i+2]], scale);
      const c = lobe.colour, rgb = [parseInt(c.slice(1, 3), 16), parseInt(c.slice(3, 5), 16),
                                    parseInt(c.slice(5, 7), 16)];
      for (let t = 0; t < tris.length; t += 3) {
        const a = proj[tris[t]], b = proj[tris[t+1]], d = proj[tris[t+2]];
        if (!a || !b || !d) continue;   // points and triangles of different grids, mid-update
        // flat shading by the normal's component along the view (light from the viewer)
        const p = a[3], q = b[3], r = d[3];
        const ux = q[0]-p[0], uy = q[1]-p[1], uz = q[2]-p[2];
        const vx = r[0]-p[0], vy = r[1]-p[1], vz = r[2]-p[2];
        const nx = uy*vz - uz*vy, ny = uz*vx - ux*vz, nz = ux*vy - uy*vx;
        const len = Math.hypot(nx, ny, nz);
        if (len === 0) continue;
        faces.push([(a[2] + b[2] + d[2]) / 3, a, b, d, 0.35 + 0.65 * Math.abs(ny) / len, rgb]);
      }
    }
    faces.sort((f, g) => g[0] - f[0]);
    for (const [, a, b, d, shade, rgb] of faces) {
      ctx.beginPath(); ctx.moveTo(a[0], a[1]); ctx.lineTo(b[0], b[1]); ctx.lineTo(d[0], d[1]);
      ctx.closePath();
      const col = `rgb(${rgb[0]*shade|0},${rgb[1]*shade|0},${rgb[2]*shade|0})`;
      ctx.fillStyle = col; ctx.fill();
    }
    // measured samples: open circles in the lobe's colour, over the surfaces
    let samples = 0;
    for (const lobe of model.lobes) {
      if (!lobe.samples) continue;
      const bytes = Uint8Array.from(atob(lobe.samples), ch => ch.charCodeAt(0));
      const pts = new Float32Array(bytes.buffer);
      ctx.strokeStyle = "#000000"; ctx.lineWidth = 1;
      for (let i = 0; i < pts.length; i += 3) {
        const q = project([pts[i], pts[i+1], pts[i+2]], scale);
        ctx.beginPath(); ctx.arc(q[0], q[1], 2.5, 0, 2 * Math.PI); ctx.stroke();
        samples++;
      }
    }
    canvas.dataset.samples = samples;
    // the incident direction (towards the light) and the normal
    const o = project([0, 0, 0], scale);
    for (const [v, colour] of [[model.incident, "#e07b00"], [[0, 0, ARROW], "#000000"]]) {
      const q = project(v, scale);
      ctx.beginPath(); ctx.moveTo(o[0], o[1]); ctx.lineTo(q[0], q[1]);
      ctx.strokeStyle = colour; ctx.lineWidth = 2; ctx.stroke();
    }
    // the incident arrow's tip: a handle to drag
    const tip = project(model.incident, scale);
    ctx.beginPath(); ctx.arc(tip[0], tip[1], 5, 0, 2 * Math.PI);
    ctx.fillStyle = "#e07b00"; ctx.fill();
    canvas.dataset.incidentTip = `${tip[0].toFixed(1)},${tip[1].toFixed(1)}`;
    canvas.dataset.view = `${model.yaw},${model.pitch},${model.zoom}`;
    canvas.dataset.drawMs = (performance.now() - t0).toFixed(2);
    canvas.dataset.faces = faces.length;
    canvas.dataset.drawn = (+canvas.dataset.drawn || 0) + 1;
  }

  function pointer(e) {
    // the pointer in canvas pixels (the canvas may be drawn at another size than its own)
    const box = canvas.getBoundingClientRect();
    return [(e.clientX - box.left) * canvas.width / box.width,
            (e.clientY - box.top) * canvas.height / box.height];
  }

  function direction(e) {
    // the incident direction under the pointer: where the view ray meets the sphere of the
    // arrow's length, the nearer point if it is above the surface, else the farther; off the
    // sphere, its silhouette; below the surface, the horizon (theta_i at most 89 degrees)
    const [sx, sy] = pointer(e), scale = 0.42 * model.size * model.zoom;
    let x = (sx - model.size / 2) / scale, up = (model.size * 0.62 - sy) / scale;
    const rim = x * x + up * up;
    if (rim >= ARROW * ARROW) {
      const k = ARROW / Math.sqrt(rim);
      x *= k; up *= k;
    }
    const depth = Math.sqrt(Math.max(ARROW * ARROW - x * x - up * up, 0));
    let p = unrotate([x, -depth, up], model.yaw, model.pitch);
    if (p[2] < 0) {
      const far = unrotate([x, depth, up], model.yaw, model.pitch);
      if (far[2] >= 0) p = far;
    }
    const len = Math.hypot(p[0], p[1], p[2]);
    const theta = Math.min(89, Math.acos(Math.max(-1, Math.min(1, p[2] / len))) * 180 / Math.PI);
    const phi = ((Math.atan2(p[1], p[0]) * 180 / Math.PI) % 360 + 360) % 360;
    return [theta, phi];
  }

  let serial = 0, sent = 0;
  function aim(e, final) {
    const [theta, phi] = direction(e), t = theta * Math.PI / 180, f = phi * Math.PI / 180;
    // the arrow follows the pointer at once; the views follow when the server answers
    model.incident = [ARROW * Math.sin(t) * Math.cos(f), ARROW * Math.sin(t) * Math.sin(f),
                      ARROW * Math.cos(t)];
    const now = performance.now();
    if (final || now - sent >= DRAG_EVERY_MS) {
      sent = now;
      model.drag = [theta, phi, final ? 1 : 0, ++serial];
    }
  }

  canvas.addEventListener("pointerdown", e => {
    const [sx, sy] = pointer(e), tip = canvas.dataset.incidentTip.split(",").map(Number);
    const onTip = Math.hypot(sx - tip[0], sy - tip[1]) <= 12;
    dragging = [e.clientX, e.clientY, model.yaw, model.pitch, onTip || e.shiftKey];
    canvas.style.cursor = dragging[4] ? "crosshair" : "grabbing";
    canvas.setPointerCapture(e.pointerId);
  });
  canvas.addEventListener("pointermove", e => {
    if (!dragging) {
      const [sx, sy] = pointer(e), tip = (canvas.dataset.incidentTip || "0,0").split(",");
      canvas.style.cursor = Math.hypot(sx - tip[0], sy - tip[1]) <= 12 ? "crosshair" : "grab";
      return;
    }
    if (dragging[4]) { aim(e, false); return; }
    model.yaw = dragging[2] + 0.01 * (e.clientX - dragging[0]);
    model.pitch = Math.max(-1.55, Math.min(1.55, dragging[3] + 0.01 * (e.clientY - dragging[1])));
    schedule();
  });
  canvas.addEventListener("pointerup", e => {
    if (dragging && dragging[4]) aim(e, true);
    dragging = null;
    canvas.style.cursor = "grab";
  });
  canvas.addEventListener("wheel", e => {
    e.preventDefault();
    model.zoom = Math.max(0.2, Math.min(10, model.zoom * Math.exp(-0.001 * e.deltaY)));
    schedule();
  }, { passive: false });
  // one drawing per frame while the view is turned or zoomed in the page
  let pending = false;
  function schedule() {
    if (pending) return;
    pending = true;
    requestAnimationFrame(() => { pending = false; draw(); });
  }
  // the server's update: drawn as soon as all its properties have been applied (a microtask
  // runs once the message's task is done), not at the next animation frame, which a busy
  // headless page gives 40-60 ms later (benchmarks/bench_explore.py)
  let queued = false;
  function update() {
    if (queued) return;
    queued = true;
    queueMicrotask(() => { queued = false; draw(); });
  }
  for (const name of ["lobes", "triangles", "incident"]) model.on(name, update);
  for (const name of ["yaw", "pitch", "zoom"]) model.on(name, schedule);
  draw();
  return canvas;
}
"""


def lobe_canvas_class():
    """The view's Panel component class (made on first use: Panel is an optional extra)."""
    global _CLASS
    if _CLASS is None:
        import param
        from panel.custom import JSComponent

        class LobeCanvas(JSComponent):
            """Lobes as ``[{"points": "base64 float32 x0 y0 z0 x1 ...", "colour": "#rrggbb",
            "samples": "base64 float32 ..." (measured points, optional)}]`` over the shared
            ``triangles`` (flat indices), the ``incident`` direction, and the view's
            ``yaw`` and ``pitch`` (radians) and ``zoom``; ``drag`` comes from the page."""

            lobes = param.List(default=[])
            triangles = param.List(default=[])
            incident = param.List(default=[0.0, 0.0, 1.0])
            yaw = param.Number(default=-0.6)
            pitch = param.Number(default=0.35)
            zoom = param.Number(default=1.0)
            size = param.Integer(default=420)
            #: set by the page while the incident arrow is dragged: theta_i and phi_i
            #: (degrees), 1 when let go (else 0), and a count that makes every one new
            drag = param.List(default=[])
            # the page's drags reach Python at once, not after Panel's usual 50 ms wait
            # (the page already sends them at most every DRAG_EVERY_MS)
            _debounce = 0
            _esm = (f"const ARROW = {ARROW}, DRAG_EVERY_MS = {DRAG_EVERY_MS};\n" + _ESM)

        _CLASS = LobeCanvas
    return _CLASS


_CLASS = None


def lobe_entry(points, colour):
    """A lobe as the view takes it: its points as base64 of little-endian float32 (x, y, z)."""
    import base64
    data = np.ascontiguousarray(points, dtype="<f4").tobytes()
    return {"points": base64.b64encode(data).decode("ascii"), "colour": colour}
