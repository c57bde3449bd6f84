// The report's 3D view (see report_html.rs). Site frame, z up, metres. `THREE` is defined by the
// inlined three.js just above this script.
const data = JSON.parse(document.getElementById('kodama-data').textContent);
const bytes = (s) => {
  const b = atob(s);
  const u = new Uint8Array(b.length);
  for (let i = 0; i < b.length; i++) u[i] = b.charCodeAt(i);
  return u.buffer;
};

const canvas = document.getElementById('c');
const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
const BACKGROUND = new THREE.Color(0xeef2f5);
const scene = new THREE.Scene();
scene.background = BACKGROUND;
const camera = new THREE.PerspectiveCamera(40, 1, 0.5, 50000);
camera.up.set(0, 0, 1);
scene.add(new THREE.HemisphereLight(0xffffff, 0x8090a0, 1.6));
const sun = new THREE.DirectionalLight(0xffffff, 1.8);
sun.position.set(-0.4, -0.7, 1.2);
scene.add(sun);

// Scenes, one group each, coloured by ITU class.
const layers = [];
const bounds = new THREE.Box3();
const materials = new Map();
data.scenes.forEach((s, i) => {
  const g = new THREE.Group();
  for (const m of s.groups) {
    const geo = new THREE.BufferGeometry();
    geo.setAttribute('position', new THREE.BufferAttribute(new Float32Array(bytes(m.positions)), 3));
    geo.setIndex(new THREE.BufferAttribute(new Uint32Array(bytes(m.indices)), 1));
    const colour = new THREE.Color(...m.colour);
    // Vertices are shared across a solid's edges: shade each face flat.
    g.add(new THREE.Mesh(geo, new THREE.MeshLambertMaterial({ color: colour, side: THREE.DoubleSide, flatShading: true })));
    materials.set(m.material, colour);
  }
  g.visible = i === 0;
  if (i === 0) bounds.setFromObject(g);
  scene.add(g);
  layers.push([s.name, g]);
});

// The radio map, draped over the terrain 0.3 m up.
let mapLegend = '';
if (data.radio_map) {
  const r = data.radio_map;
  const h = new Float32Array(bytes(r.heights));
  const geo = new THREE.PlaneGeometry(r.cell * (r.width - 1), r.cell * (r.height - 1), r.width - 1, r.height - 1);
  const pos = geo.attributes.position;
  // PlaneGeometry's vertices run row by row from the top (+y) edge, as the raster's rows do.
  for (let k = 0; k < pos.count; k++) pos.setZ(k, h[k] + 0.3);
  geo.computeVertexNormals();
  const tex = new THREE.TextureLoader().load('data:image/png;base64,' + r.png, () => render());
  tex.magFilter = THREE.NearestFilter;
  tex.colorSpace = THREE.SRGBColorSpace;
  const mesh = new THREE.Mesh(geo, new THREE.MeshBasicMaterial({ map: tex, transparent: true, depthWrite: false }));
  mesh.position.set(r.x0 + r.cell * (r.width / 2), r.y0 - r.cell * (r.height / 2), 0);
  scene.add(mesh);
  layers.push(['radio map (dB)', mesh]);
  mapLegend = `radio map <span class="bar" style="background:linear-gradient(90deg,#440154,#3b528b,#21918c,#5ec962,#fde725)"></span>${r.lo.toFixed(0)} to ${r.hi.toFixed(0)} dB`;
}

// Measured points, coloured by the first model's error (blue: predicted too low a loss, red: too high).
const errColour = (e) => {
  const t = Math.max(-1, Math.min(1, e / 15));
  return t < 0 ? new THREE.Color(1 + t, 1 + t * 0.6, 1) : new THREE.Color(1, 1 - t * 0.8, 1 - t);
};
let pointsMesh = null;
if (data.points.length) {
  const pos = new Float32Array(data.points.length * 3);
  const col = new Float32Array(data.points.length * 3);
  data.points.forEach((p, i) => {
    pos.set([p.at[0], p.at[1], p.at[2] + 1.5], 3 * i);
    const e = p.predicted[0] != null && p.measured != null ? p.predicted[0] - p.measured : null;
    const c = e == null ? new THREE.Color(0.4, 0.4, 0.4) : errColour(e);
    col.set([c.r, c.g, c.b], 3 * i);
  });
  const geo = new THREE.BufferGeometry();
  geo.setAttribute('position', new THREE.BufferAttribute(pos, 3));
  geo.setAttribute('color', new THREE.BufferAttribute(col, 3));
  pointsMesh = new THREE.Points(geo, new THREE.PointsMaterial({ size: 7, sizeAttenuation: false, vertexColors: true }));
  scene.add(pointsMesh);
  layers.push(['measured points', pointsMesh]);
}

// Toggles and legend.
const panel = document.getElementById('panel');
for (const [name, obj] of layers) {
  const l = document.createElement('label');
  const cb = document.createElement('input');
  cb.type = 'checkbox';
  cb.checked = obj.visible;
  cb.onchange = () => { obj.visible = cb.checked; render(); };
  l.append(cb, ' ' + name);
  panel.append(l);
}
const legend = document.getElementById('legend');
let html = '';
for (const [name, c] of materials) html += `<span class="sw" style="background:#${c.getHexString()}"></span>${name}`;
if (mapLegend) html += `<br>${mapLegend}`;
if (data.left_out.length) html += `<br>left out (too large for a page): ${data.left_out.join(', ')}`;
if (pointsMesh) html += `<br>points: ${data.models[0]} error <span class="bar" style="background:linear-gradient(90deg,#0066ff,#fff,#ff0000)"></span>-15 to +15 dB`;
legend.innerHTML = html;

// Orbit, pan and zoom about a target, z up.
const target = bounds.isEmpty() ? new THREE.Vector3() : bounds.getCenter(new THREE.Vector3());
const size = bounds.isEmpty() ? 100 : bounds.getSize(new THREE.Vector3()).length();
let azimuth = -0.6, elevation = 0.7, distance = size * 0.9;
const place = () => {
  const ce = Math.cos(elevation);
  camera.position.set(
    target.x + distance * ce * Math.sin(azimuth),
    target.y - distance * ce * Math.cos(azimuth),
    target.z + distance * Math.sin(elevation));
  camera.lookAt(target);
};
let drag = null;
canvas.addEventListener('contextmenu', (e) => e.preventDefault());
canvas.addEventListener('pointerdown', (e) => {
  drag = { x: e.clientX, y: e.clientY, pan: e.button === 2 || e.shiftKey, moved: false };
  canvas.setPointerCapture(e.pointerId);
});
canvas.addEventListener('pointermove', (e) => {
  if (!drag) return;
  const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
  if (Math.abs(dx) + Math.abs(dy) > 2) drag.moved = true;
  drag.x = e.clientX; drag.y = e.clientY;
  if (drag.pan) {
    const s = distance / canvas.clientHeight;
    const right = new THREE.Vector3(Math.cos(azimuth), Math.sin(azimuth), 0);
    const fwd = new THREE.Vector3(-Math.sin(azimuth), Math.cos(azimuth), 0);
    target.addScaledVector(right, -dx * s).addScaledVector(fwd, dy * s);
  } else {
    azimuth -= dx * 0.005;
    elevation = Math.max(0.05, Math.min(1.55, elevation + dy * 0.005));
  }
  render();
});
canvas.addEventListener('pointerup', (e) => {
  if (drag && !drag.moved) pick(e);
  drag = null;
});
canvas.addEventListener('wheel', (e) => {
  e.preventDefault();
  distance = Math.max(5, Math.min(size * 5, distance * Math.exp(e.deltaY * 0.001)));
  render();
}, { passive: false });

// A click on a point: its link's measurement and every model's prediction.
const ray = new THREE.Raycaster();
ray.params.Points.threshold = 3;
const info = document.getElementById('info');
const fmt = (v) => (v == null ? '–' : v.toFixed(1));
function pick(e) {
  if (!pointsMesh || !pointsMesh.visible) return;
  const r = canvas.getBoundingClientRect();
  ray.setFromCamera(new THREE.Vector2(((e.clientX - r.left) / r.width) * 2 - 1, -((e.clientY - r.top) / r.height) * 2 + 1), camera);
  const hit = ray.intersectObject(pointsMesh)[0];
  if (!hit) { info.style.display = 'none'; return; }
  const p = data.points[hit.index];
  let rows = `<tr><th>measured</th><td>${fmt(p.measured)} dB</td><td></td></tr>`;
  data.models.forEach((m, k) => {
    const v = p.predicted[k];
    const err = v != null && p.measured != null ? v - p.measured : null;
    rows += `<tr><th>${m}</th><td>${fmt(v)} dB</td><td>${err == null ? '' : (err > 0 ? '+' : '') + err.toFixed(1)}</td></tr>`;
  });
  info.innerHTML = `<b>link ${hit.index + 1}</b> at (${p.at[0].toFixed(0)}, ${p.at[1].toFixed(0)}) m<table>${rows}</table>`;
  info.style.display = 'block';
}

function resize() {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  renderer.setSize(w, h, false);
  camera.aspect = w / Math.max(h, 1);
  camera.updateProjectionMatrix();
}
function render() {
  place();
  renderer.render(scene, camera);
}
window.addEventListener('resize', () => { resize(); render(); });
resize();
render();

// For headless checks: the share of canvas pixels that are not the background.
const gl = renderer.getContext();
const w = gl.drawingBufferWidth, h = gl.drawingBufferHeight;
const px = new Uint8Array(w * h * 4);
gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
const bg = BACKGROUND.clone().convertLinearToSRGB();
const [br, bgc, bb] = [bg.r, bg.g, bg.b].map((v) => Math.round(v * 255));
let differ = 0;
for (let i = 0; i < px.length; i += 4) {
  if (Math.abs(px[i] - br) + Math.abs(px[i + 1] - bgc) + Math.abs(px[i + 2] - bb) > 12) differ++;
}
document.body.dataset.nonblank = (differ / (w * h)).toFixed(3);
document.body.dataset.ready = '1';
