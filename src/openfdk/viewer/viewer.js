// openfdk view: plays one run in 3D (three.js, inlined). Data: the JSON block
// #openfdk-data written by openfdk.viewer (SI units; poses r_WB and Euler parameters
// e0..e3 per body and frame). URL hash parameters (also ?query):
//   t=SECONDS | frame=K     start at this time / frame (paused)
//   view=anterior|posterior|left|right|superior|inferior|oblique
//   cam=ex,ey,ez,tx,ty,tz   camera eye and target (m, world); fov=DEG (vertical)
//   ui=0                    hide the panels;  play=1  start playing;  speed=X
//   fit=1                   press F (fit) once ready
//   hide=LAYER,...          start with these layers off (frames, meshes, markers, paths, contact, ...)
//   hover=X,Y               show (and log) the tooltip of the path under css pixel X,Y
//   probe=BODY              draw BODY's origin as an unlit magenta disc on top (tests)
(async function () {
  'use strict';
  const $ = (id) => document.getElementById(id);
  const say = (s) => { console.log('openfdk-view: ' + s); };
  function fail(msg) {
    document.body.dataset.status = 'error';
    const e = $('error'); e.style.display = 'block'; e.textContent = 'openfdk view: ' + msg;
    say('error ' + msg);
  }
  window.addEventListener('error', (ev) => fail(String(ev.message)));
  let THREE, OrbitControls;
  try {
    const url = (text) => URL.createObjectURL(new Blob([text], { type: 'text/javascript' }));
    const core = url($('three-core').textContent);
    const mod = url($('three-module').textContent.replace(/from\s*'\.\/three\.core\.js'/g, "from '" + core + "'"));
    const orbit = url($('three-orbit').textContent.replace(/from\s*'three'/g, "from '" + mod + "'"));
    THREE = await import(mod);
    ({ OrbitControls } = await import(orbit));
  } catch (err) { fail('could not start three.js: ' + err); return; }

  const D = JSON.parse($('openfdk-data').textContent);
  const KINDS = { f32: Float32Array, u32: Uint32Array, u16: Uint16Array, u8: Uint8Array, i32: Int32Array };
  function arr(o) {
    if (!o) return null;
    const bin = atob(o.b64), n = bin.length, bytes = new Uint8Array(n);
    for (let i = 0; i < n; i++) bytes[i] = bin.charCodeAt(i);
    return new KINDS[o.dtype](bytes.buffer);
  }
  const params = new URLSearchParams(location.search.slice(1) + '&' + location.hash.slice(1));
  const S = D.scene, F = D.frames;
  const time = arr(F.time), nf = time.length, nb = S.bodies.length;
  const poses = arr(F.poses), measured = arr(F.measured), pathForce = arr(F.path_force);
  const scale = S.scale;
  const probe = params.get('probe');
  const showUI = params.get('ui') !== '0';
  if (!showUI) for (const id of ['panel', 'controls', 'views', 'legend']) $(id).style.display = 'none';
  $('title').textContent = D.meta.title;

  // -- renderer, camera, lights ------------------------------------------------------
  const canvas = $('view');
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: !probe, preserveDrawingBuffer: true });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.setSize(window.innerWidth, window.innerHeight, false);
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0xf3f3f1);
  const fov = parseFloat(params.get('fov') || '35');
  const camera = new THREE.PerspectiveCamera(fov, window.innerWidth / window.innerHeight, scale * 1e-3, scale * 200);
  const g = new THREE.Vector3(...S.gravity);
  const up = g.lengthSq() > 0 ? g.clone().negate().normalize() : new THREE.Vector3(0, 0, 1);
  let anterior = new THREE.Vector3(1, 0, 0).projectOnPlane(up);
  if (anterior.lengthSq() < 1e-6) anterior = new THREE.Vector3(0, 1, 0).projectOnPlane(up);
  anterior.normalize();
  const left = new THREE.Vector3().crossVectors(up, anterior);
  camera.up.copy(up);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x666666, 1.6));
  const sun = new THREE.DirectionalLight(0xffffff, 1.4); camera.add(sun); sun.position.set(0.3, 0.6, 0.2); scene.add(camera);
  const controls = new OrbitControls(camera, canvas);
  controls.enableDamping = false;
  controls.addEventListener('change', () => render());
  controls.addEventListener('start', () => { autoFramed = false; });

  const PRESETS = {
    anterior: [anterior, up], posterior: [anterior.clone().negate(), up], left: [left, up],
    right: [left.clone().negate(), up], superior: [up, anterior], inferior: [up.clone().negate(), anterior],
    oblique: [anterior.clone().add(left.clone().multiplyScalar(0.8)).add(up.clone().multiplyScalar(0.5)).normalize(), up],
  };
  // framing: the box of what moves over the trial (F.bounds, m world), seen in the part of
  // the canvas the side panel leaves free; the view centre is shifted there (setViewOffset)
  const B = F.bounds || { min: S.center.map((c) => c - scale / 2), max: S.center.map((c) => c + scale / 2) };
  const boxMin = new THREE.Vector3(...B.min), boxMax = new THREE.Vector3(...B.max);
  const center = boxMin.clone().add(boxMax).multiplyScalar(0.5);
  const extent = Math.max(boxMax.distanceTo(boxMin), scale * 0.1, 1e-3);
  const FILL = 0.85;  // the box fills this fraction of the free canvas in its tighter direction
  function visibleRect() {  // [x0, y0, x1, y1] css px of the canvas not covered by the side panel
    const W = window.innerWidth, H = window.innerHeight, p = $('panel');
    if (!showUI || p.style.display === 'none') return [0, 0, W, H];
    const r = p.getBoundingClientRect();
    return r.left > W * 0.3 ? [0, 0, r.left, H] : [0, 0, W, H];
  }
  function applyOffset() {
    const W = window.innerWidth, H = window.innerHeight, [x0, , x1] = visibleRect();
    const dx = W / 2 - (x0 + x1) / 2;  // the principal point at the centre of the free part
    if (dx !== 0) camera.setViewOffset(W, H, dx, 0, W, H); else camera.clearViewOffset();
    camera.aspect = W / H; camera.updateProjectionMatrix();
  }
  // eye distance along dir (unit, target -> eye) so that the box fits the free canvas
  function fitDistance(dir, u) {
    const f = dir.clone().negate(), r = new THREE.Vector3().crossVectors(f, u).normalize();
    const uu = new THREE.Vector3().crossVectors(r, f);
    const [x0, y0, x1, y1] = visibleRect();
    const tanV = Math.tan(THREE.MathUtils.degToRad(fov) / 2), H = window.innerHeight;
    const tanY = tanV * (y1 - y0) / H * FILL, tanX = tanV * (x1 - x0) / H * FILL;
    let d = 0;
    const p = new THREE.Vector3();
    for (let c = 0; c < 8; c++) {
      p.set(c & 1 ? boxMax.x : boxMin.x, c & 2 ? boxMax.y : boxMin.y, c & 4 ? boxMax.z : boxMin.z).sub(center);
      const z = p.dot(f);
      d = Math.max(d, Math.abs(p.dot(r)) / tanX - z, Math.abs(p.dot(uu)) / tanY - z);
    }
    return Math.max(d, extent * 0.6);
  }
  let autoFramed = false;  // the camera is where a preset/fit put it: re-fit on resize
  function frameView(dir, u) {
    autoFramed = true;
    const dist = fitDistance(dir, u);
    camera.near = Math.max(dist * 1e-3, 1e-5); camera.far = dist * 50 + extent * 10;
    applyOffset();
    camera.up.copy(u);
    camera.position.copy(center).addScaledVector(dir, dist);
    controls.target.copy(center);
    camera.lookAt(center);
    controls.update();
    render();
  }
  function cameraInfo() {  // what the tests need to project points as the page does
    return { width: window.innerWidth, height: window.innerHeight, fov, eye: camera.position.toArray(),
      target: controls.target.toArray(), up: camera.up.toArray(), visible: visibleRect(),
      offset: camera.view && camera.view.enabled ? [camera.view.offsetX, camera.view.offsetY] : [0, 0],
      bounds: [boxMin.toArray(), boxMax.toArray()] };
  }
  function setView(name) { const [dir, u] = PRESETS[name] || PRESETS.oblique; frameView(dir, u); }
  // fit (F): keep the direction of view, frame the motion again
  function fit() {
    const dir = camera.position.clone().sub(controls.target);
    if (dir.lengthSq() === 0) dir.copy(PRESETS.oblique[0]);
    frameView(dir.normalize(), camera.up.clone());
  }

  // -- bodies: frames (axes + origin sphere) and meshes --------------------------------
  const groups = [];
  const layers = { frames: [], meshes: [], markers: [], paths: [], contact: [] };
  for (const b of S.bodies) {
    const grp = new THREE.Group(); grp.name = b.name;
    grp.position.set(...b.p0); grp.quaternion.set(b.q0[1], b.q0[2], b.q0[3], b.q0[0]);
    const axes = new THREE.AxesHelper(scale * 0.08); grp.add(axes); layers.frames.push(axes);
    const isProbe = probe === b.name;
    const dot = new THREE.Mesh(new THREE.SphereGeometry(scale * (isProbe ? 0.03 : 0.012), 20, 12),
      isProbe ? new THREE.MeshBasicMaterial({ color: 0xff00ff, depthTest: false, transparent: true })  // drawn last, over translucent meshes
              : new THREE.MeshStandardMaterial({ color: b.color }));
    if (isProbe) dot.renderOrder = 10; else layers.frames.push(dot);
    grp.add(dot);
    const hasMesh = S.meshes.some((m) => S.bodies[m.body] === b);
    if (b.points.length && !hasMesh) {  // no mesh: a stick from the origin to each frame/point of the body
      const sticks = new Float32Array(6 * b.points.length);
      b.points.forEach((p, j) => sticks.set(p, 6 * j + 3));
      const sg = new THREE.BufferGeometry(); sg.setAttribute('position', new THREE.BufferAttribute(sticks, 3));
      const st = new THREE.LineSegments(sg, new THREE.LineBasicMaterial({ color: b.color }));
      grp.add(st); layers.frames.push(st);
    }
    scene.add(grp); groups.push(grp);
  }
  const meshObjects = [];
  for (const m of S.meshes) {
    const geo = new THREE.BufferGeometry();
    geo.setAttribute('position', new THREE.BufferAttribute(arr(m.vertices), 3));
    geo.setIndex(new THREE.BufferAttribute(m.faces.dtype === 'u32' ? arr(m.faces) : new Uint32Array(arr(m.faces)), 1));
    geo.computeVertexNormals();
    const base = new THREE.Color(m.color);
    const mat = new THREE.MeshStandardMaterial({ color: 0xffffff, side: THREE.DoubleSide, roughness: 0.8,
      vertexColors: true, transparent: m.kind === 'visual', opacity: m.kind === 'visual' ? 0.75 : 1 });
    const nv = geo.attributes.position.count, col = new Float32Array(3 * nv);
    for (let i = 0; i < nv; i++) { col[3 * i] = base.r; col[3 * i + 1] = base.g; col[3 * i + 2] = base.b; }
    geo.setAttribute('color', new THREE.BufferAttribute(col, 3));
    const obj = new THREE.Mesh(geo, mat);
    groups[m.body].add(obj);
    meshObjects.push({ obj, base, col, lit: [] });
    (m.kind === 'visual' ? layers.meshes : layers.contact).push(obj);
  }
  // wrapping surfaces, semi-transparent on their bodies (a cylinder's axis is its frame's z)
  for (const w of S.wrap_surfaces || []) {
    const geo = w.kind === 'cylinder'
      ? new THREE.CylinderGeometry(w.dims[0], w.dims[0], w.length, 32, 1, true).rotateX(Math.PI / 2)
      : new THREE.SphereGeometry(1, 32, 16).scale(w.dims[0], w.dims[1], w.dims[2]);
    const obj = new THREE.Mesh(geo, new THREE.MeshStandardMaterial({ color: 0x8fb3d9, transparent: true, opacity: 0.3,
      depthWrite: false, side: THREE.DoubleSide, roughness: 0.9 }));
    const R = w.R_BS;
    obj.quaternion.setFromRotationMatrix(new THREE.Matrix4().set(R[0][0], R[0][1], R[0][2], 0, R[1][0], R[1][1], R[1][2], 0,
      R[2][0], R[2][1], R[2][2], 0, 0, 0, 0, 1));
    obj.position.set(w.p_BS[0], w.p_BS[1], w.p_BS[2]);
    obj.userData.name = `wrapping surface ${w.name} (${w.kind})`;
    groups[w.body].add(obj);
    layers.paths.push(obj);
  }

  // -- markers and residual lines --------------------------------------------------------
  const nm = S.markers.names.length;
  const sphere = new THREE.SphereGeometry(scale * 0.008, 12, 8);
  const modelMarkers = new THREE.InstancedMesh(sphere, new THREE.MeshStandardMaterial({ color: 0x1f5fbf, transparent: true, opacity: 0.45, depthWrite: false }), Math.max(nm, 1));
  const measMarkers = new THREE.InstancedMesh(new THREE.SphereGeometry(scale * 0.0055, 12, 8), new THREE.MeshStandardMaterial({ color: 0xf08c00 }), Math.max(nm, 1));
  modelMarkers.count = nm; measMarkers.count = measured ? nm : 0;
  const resGeo = new THREE.BufferGeometry();
  resGeo.setAttribute('position', new THREE.BufferAttribute(new Float32Array(6 * Math.max(nm, 1)), 3));
  const resLines = new THREE.LineSegments(resGeo, new THREE.LineBasicMaterial({ color: 0xd00000 }));
  resLines.frustumCulled = false; modelMarkers.frustumCulled = false; measMarkers.frustumCulled = false;
  scene.add(modelMarkers, measMarkers, resLines);
  layers.markers.push(modelMarkers, measMarkers, resLines);

  // -- force paths (muscles, ligaments, springs) ------------------------------------------
  // a chain of body points moves with its bodies; a wrapped path (p.wrap) is a slice of the
  // per-frame world polylines F.wrap_points (nf, n_wrap_points, 3), fixed count per path
  const wrapPoints = arr(F.wrap_points), nWrap = wrapPoints ? wrapPoints.length / (3 * nf) : 0;
  const nPoints = (p) => (p.wrap ? p.wrap.count : p.points.length);
  let nseg = 0; for (const p of S.paths) nseg += nPoints(p) - 1;
  const pathGeo = new THREE.BufferGeometry();
  pathGeo.setAttribute('position', new THREE.BufferAttribute(new Float32Array(6 * Math.max(nseg, 1)), 3));
  pathGeo.setAttribute('color', new THREE.BufferAttribute(new Float32Array(6 * Math.max(nseg, 1)), 3));
  pathGeo.setDrawRange(0, 2 * nseg);
  // drawn as tubes: one open cylinder per segment (instanced), radius p.radius_m by strength
  const tubeGeo = new THREE.CylinderGeometry(1, 1, 1, 10, 1, true);
  const tubes = new THREE.InstancedMesh(tubeGeo, new THREE.MeshStandardMaterial({ color: 0xffffff, roughness: 0.6 }),
    Math.max(nseg, 1));
  tubes.count = nseg; tubes.frustumCulled = false;
  const segPath = new Int32Array(Math.max(nseg, 1));
  { let s0 = 0; S.paths.forEach((p, j) => { for (let e = 0; e + 1 < nPoints(p); e++) segPath[s0++] = j; }); }
  if (nseg) tubes.setColorAt(0, new THREE.Color());
  scene.add(tubes); layers.paths.push(tubes);
  const yAxis = new THREE.Vector3(0, 1, 0), segA = new THREE.Vector3(), segB = new THREE.Vector3();
  const segMid = new THREE.Vector3(), segDir = new THREE.Vector3(), segQ = new THREE.Quaternion(), segS = new THREE.Vector3();
  const segC = new THREE.Color();
  function placeTubes() {
    const pp = pathGeo.attributes.position.array, pc = pathGeo.attributes.color.array;
    for (let k = 0; k < nseg; k++) {
      const r = S.paths[segPath[k]].radius_m || scale * 0.003;
      segA.fromArray(pp, 6 * k); segB.fromArray(pp, 6 * k + 3);
      segDir.subVectors(segB, segA);
      const len = segDir.length();
      segMid.addVectors(segA, segB).multiplyScalar(0.5);
      if (len > 0) segQ.setFromUnitVectors(yAxis, segDir.divideScalar(len)); else segQ.identity();
      segS.set(len > 0 ? r : 0, len, len > 0 ? r : 0);
      tubes.setMatrixAt(k, m4.compose(segMid, segQ, segS));
      tubes.setColorAt(k, segC.setRGB(pc[6 * k], pc[6 * k + 1], pc[6 * k + 2]));
    }
    tubes.instanceMatrix.needsUpdate = true;
    if (tubes.instanceColor) tubes.instanceColor.needsUpdate = true;
    tubes.computeBoundingSphere();
  }
  const kindMax = {};
  S.paths.forEach((p, j) => { kindMax[p.kind] = Math.max(kindMax[p.kind] || 0, F.path_fmax[j] || 0); });

  // -- contact: pressure colours and force arrows ---------------------------------------
  const contacts = F.contacts.map((c, j) => ({
    spec: S.contacts[j], p_max: c.p_max, force: arr(c.force), cop: arr(c.cop), offsets: arr(c.offsets),
    index: arr(c.index), level: arr(c.level),
    arrow: new THREE.ArrowHelper(new THREE.Vector3(0, 0, 1), new THREE.Vector3(), 1, 0xc00000),
  }));
  // force arrows {force, arrow}: the largest force over the trial of their kind is drawn
  // ARROW.length_m long (F.arrow_scale, written by Python)
  const ARROWS = F.arrow_scale || {};
  function forceArrows(items, kind) {
    for (const c of items) { scene.add(c.arrow); layers.contact.push(c.arrow); }
    return ARROWS[kind] || { fmax: 0, length_m: scale * 0.35 };
  }
  const fContactMax = forceArrows(contacts, 'contact');
  // ground reactions (grf.csv): a green arrow per plate at its centre of pressure
  const grfs = (F.grf || []).map((g) => ({
    name: g.name, force: arr(g.force), cop: arr(g.cop),
    arrow: new THREE.ArrowHelper(new THREE.Vector3(0, 0, 1), new THREE.Vector3(), 1, 0x1a8c1a),
  }));
  const fGrfMax = forceArrows(grfs, 'grf');
  // one-sided joint reactions of POP models (the TMJ contacts): a purple arrow at the point on the plane
  const reacts = (F.reactions || []).map((g) => ({
    name: g.name, force: arr(g.force), cop: arr(g.cop),
    arrow: new THREE.ArrowHelper(new THREE.Vector3(0, 0, 1), new THREE.Vector3(), 1, 0x8a2be2),
  }));
  const fReactMax = forceArrows(reacts, 'reaction');
  // joint loads (joint_loads.csv, an OpenSim model's joints): a purple arrow at each joint
  // centre, the force the joint applies to its child body
  const jloads = (F.joint_loads || []).map((g) => ({
    name: g.name, force: arr(g.force), cop: arr(g.cop),
    arrow: new THREE.ArrowHelper(new THREE.Vector3(0, 0, 1), new THREE.Vector3(), 1, 0x8a2be2),
  }));
  const fJointMax = forceArrows(jloads, 'joint_load');
  // legend text of an arrow scale: "<length> mm = <force> N"
  const arrowText = (a) => `${(a.length_m * 1e3).toPrecision(3)} mm = ${a.fmax.toPrecision(3)} N`;

  // colour maps: pressure/force 0..1 -> blue, cyan, green, yellow, red
  const STOPS = [[0.19, 0.30, 0.75], [0.10, 0.70, 0.85], [0.30, 0.75, 0.30], [0.95, 0.85, 0.15], [0.85, 0.10, 0.10]];
  function cmap(x, out) {
    x = Math.min(1, Math.max(0, x)) * (STOPS.length - 1);
    const i = Math.min(STOPS.length - 2, Math.floor(x)), u = x - i, a = STOPS[i], b = STOPS[i + 1];
    out[0] = a[0] + u * (b[0] - a[0]); out[1] = a[1] + u * (b[1] - a[1]); out[2] = a[2] + u * (b[2] - a[2]);
    return out;
  }
  const css = (x) => { const c = cmap(x, [0, 0, 0]); return `rgb(${c.map((v) => Math.round(255 * v)).join(',')})`; };
  const grad = 'linear-gradient(to right,' + [0, 0.25, 0.5, 0.75, 1].map(css).join(',') + ')';
  const legend = [];
  for (const k of Object.keys(kindMax)) legend.push(`${k} force <span class="bar" style="background:${grad}"></span> 0–${kindMax[k].toPrecision(3)} ${k === 'spring' ? '' : 'N'}`);
  if (contacts.length) legend.push(`contact pressure <span class="bar" style="background:${grad}"></span> 0–${(Math.max(...contacts.map((c) => c.p_max)) / 1e6).toPrecision(3)} MPa; <b style="color:#c00000">arrow</b>: force on the vertex body` +
    (fContactMax.fmax > 0 ? `, ${arrowText(fContactMax)}` : ''));
  if (reacts.length) legend.push(`<b style="color:#8a2be2">joint reaction</b> arrows (one-sided, on the child's point), ${arrowText(fReactMax)}`);
  if (jloads.length) legend.push(`<b style="color:#8a2be2">joint load</b> arrows at each joint centre, on the child body, ${arrowText(fJointMax)}`);
  if (grfs.length) legend.push(`<b style="color:#1a8c1a">ground reaction</b> arrows at the centre of pressure, ${arrowText(fGrfMax)}`);
  if (nm) legend.push('markers: <b style="color:#1f5fbf">model</b>, <b style="color:#f08c00">measured</b>, <b style="color:#d00000">residual</b>');
  $('legend').innerHTML = legend.join('<br>');
  if (!legend.length) $('legend').style.display = 'none';

  // layer toggles (hide=a,b in the URL: start with those layers off)
  const hidden = new Set((params.get('hide') || '').split(',').filter(Boolean));
  for (const [name, objs] of Object.entries(layers)) {
    if (!objs.length) continue;
    const lab = document.createElement('label'), box = document.createElement('input');
    box.type = 'checkbox'; box.checked = !hidden.has(name);
    for (const o of objs) o.userData.hidden = !box.checked;
    box.addEventListener('change', () => { for (const o of objs) o.userData.hidden = !box.checked; setFrame(frame); });
    lab.append(box, ' ' + name); $('layers').append(lab);
  }

  // -- side panel ----------------------------------------------------------------------
  const series = F.panel.map((s) => ({ ...s, v: arr(s.values) }));
  const failed = new Map(F.failed.map(([k, msg]) => [k, msg]));
  const rows = series.map((s) => `<tr><td>${s.name}</td><td class="v" id="s-${series.indexOf(s)}"></td><td>${s.unit}</td></tr>`);
  $('panel-body').innerHTML = `<table>${rows.join('')}</table><div id="failsum"></div>` +
    `<div style="margin-top:4px;color:#555">${D.meta.lines.join('<br>')}</div>`;
  // sparklines of the non-flag series over the whole trial, with a cursor at the current frame
  const sparks = [];
  series.forEach((sr, j) => {
    if (sr.flag || sparks.length >= 10) return;
    let lo = Infinity, hi = -Infinity;
    for (const x of sr.v) if (Number.isFinite(x)) { lo = Math.min(lo, x); hi = Math.max(hi, x); }
    if (!(hi >= lo)) return;
    if (hi === lo) { hi += 1e-12 + Math.abs(hi) * 1e-6; lo -= 1e-12 + Math.abs(lo) * 1e-6; }
    const cv = document.createElement('canvas'); cv.width = 270; cv.height = 28; cv.title = sr.name;
    const row = document.createElement('tr'), td = document.createElement('td'); td.colSpan = 3; td.append(cv); row.append(td);
    $('s-' + j).parentElement.after(row);
    const ctx = cv.getContext('2d'); ctx.strokeStyle = '#4f6fa8'; ctx.beginPath();
    for (let k = 0; k < nf; k++) {
      const x = sr.v[k]; if (!Number.isFinite(x)) continue;
      const px = nf > 1 ? k / (nf - 1) * 269 : 0, py = 26 - (x - lo) / (hi - lo) * 24;
      k === 0 ? ctx.moveTo(px, py) : ctx.lineTo(px, py);
    }
    ctx.stroke();
    for (const [k] of failed) { ctx.fillStyle = 'rgba(176,0,32,0.5)'; ctx.fillRect(nf > 1 ? k / (nf - 1) * 269 : 0, 0, 1, 28); }
    sparks.push({ ctx, img: ctx.getImageData(0, 0, 270, 28) });
  });
  function drawCursors() {
    for (const sp of sparks) {
      sp.ctx.putImageData(sp.img, 0, 0); sp.ctx.fillStyle = '#d00000';
      sp.ctx.fillRect(nf > 1 ? frame / (nf - 1) * 269 : 0, 0, 1.5, 28);
    }
  }
  $('failsum').innerHTML = failed.size ? `<span class="bad">${failed.size} failed frame(s)</span>` : 'all frames converged';

  // -- per-frame update --------------------------------------------------------------------
  const v = new THREE.Vector3(), q = new THREE.Quaternion(), m4 = new THREE.Matrix4(), one = new THREE.Vector3(1, 1, 1);
  const zero = new THREE.Vector3(1e-9, 1e-9, 1e-9), rgb = [0, 0, 0];
  function worldPoint(body, x, y, z, out) { return out.set(x, y, z).applyMatrix4(groups[body].matrixWorld); }
  function visible(obj) { obj.visible = !obj.userData.hidden; return obj.visible; }
  // a force arrow {force, cop, arrow} at its centre of pressure, length by the trial's largest force
  function placeArrow(c, sc) {
    const fx = c.force[3 * frame], fy = c.force[3 * frame + 1], fz = c.force[3 * frame + 2];
    const fm = Math.hypot(fx, fy, fz), cx = c.cop[3 * frame];
    if (fm > 0 && Number.isFinite(cx) && visible(c.arrow)) {
      const len = sc.length_m * fm / (sc.fmax || 1);
      c.arrow.position.set(cx, c.cop[3 * frame + 1], c.cop[3 * frame + 2]);
      c.arrow.setDirection(v.set(fx, fy, fz).normalize());
      c.arrow.setLength(len, 0.25 * len, 0.12 * len);
    } else c.arrow.visible = false;
  }
  let frame = 0;
  function setFrame(k) {
    frame = Math.max(0, Math.min(nf - 1, k | 0));
    let posesOk = true;
    for (let i = 0; i < nb; i++) {
      const o = (frame * nb + i) * 7;
      if (!Number.isFinite(poses[o])) { posesOk = false; continue; }
      groups[i].position.set(poses[o], poses[o + 1], poses[o + 2]);
      groups[i].quaternion.set(poses[o + 4], poses[o + 5], poses[o + 6], poses[o + 3]);
      groups[i].updateMatrixWorld(true);
    }
    for (const objs of Object.values(layers)) for (const o of objs) visible(o);
    // markers
    const rp = resGeo.attributes.position.array;
    for (let j = 0; j < nm; j++) {
      const p = S.markers.p_B[j];
      worldPoint(S.markers.body[j], p[0], p[1], p[2], v);
      modelMarkers.setMatrixAt(j, m4.compose(v, q.identity(), one));
      rp[6 * j] = v.x; rp[6 * j + 1] = v.y; rp[6 * j + 2] = v.z;
      if (measured) {
        const o = (frame * nm + j) * 3, ok = Number.isFinite(measured[o]);
        const w = ok ? new THREE.Vector3(measured[o], measured[o + 1], measured[o + 2]) : v;
        measMarkers.setMatrixAt(j, m4.compose(w, q.identity(), ok ? one : zero));
        rp[6 * j + 3] = w.x; rp[6 * j + 4] = w.y; rp[6 * j + 5] = w.z;
      } else { rp[6 * j + 3] = v.x; rp[6 * j + 4] = v.y; rp[6 * j + 5] = v.z; }
    }
    modelMarkers.instanceMatrix.needsUpdate = true; measMarkers.instanceMatrix.needsUpdate = true;
    resGeo.attributes.position.needsUpdate = true;
    // paths coloured by force / the largest force of their kind over the trial
    const pp = pathGeo.attributes.position.array, pc = pathGeo.attributes.color.array;
    let s = 0;
    S.paths.forEach((p, j) => {
      const f = pathForce[frame * S.paths.length + j], mx = kindMax[p.kind] || 1;
      if (Number.isFinite(f)) cmap(Math.abs(f) / mx, rgb); else { rgb[0] = rgb[1] = rgb[2] = 0.55; }
      for (let e = 0; e + 1 < nPoints(p); e++, s++) {
        for (let h = 0; h < 2; h++) {
          if (p.wrap) {  // NaN (no pose, path not formed): collapse to the origin, invisible
            const o = 3 * (frame * nWrap + p.wrap.offset + e + h), ok = Number.isFinite(wrapPoints[o]);
            v.set(ok ? wrapPoints[o] : 0, ok ? wrapPoints[o + 1] : 0, ok ? wrapPoints[o + 2] : 0);
          } else {
            const a = p.points[e + h];
            worldPoint(a[0], a[1], a[2], a[3], v);
          }
          pp.set([v.x, v.y, v.z], 6 * s + 3 * h); pc.set(rgb, 6 * s + 3 * h);
        }
      }
    });
    pathGeo.attributes.position.needsUpdate = true; pathGeo.attributes.color.needsUpdate = true;
    placeTubes();
    // contact pressure on the vertex surface, force arrow at the centre of pressure
    for (const c of contacts) {
      const mo = meshObjects[c.spec.mesh], col = mo.col;
      for (const i of mo.lit) { col[3 * i] = mo.base.r; col[3 * i + 1] = mo.base.g; col[3 * i + 2] = mo.base.b; }
      mo.lit = [];
      for (let e = c.offsets[frame]; e < c.offsets[frame + 1]; e++) {
        const i = c.index[e]; cmap(c.level[e] / 255, rgb);
        col[3 * i] = rgb[0]; col[3 * i + 1] = rgb[1]; col[3 * i + 2] = rgb[2]; mo.lit.push(i);
      }
      mo.obj.geometry.attributes.color.needsUpdate = true;
      placeArrow(c, fContactMax);
    }
    for (const g of grfs) placeArrow(g, fGrfMax);
    for (const g of reacts) placeArrow(g, fReactMax);
    for (const g of jloads) placeArrow(g, fJointMax);
    // panel, clock, banner
    series.forEach((sr, j) => {
      const x = sr.v[frame], cell = $('s-' + j);
      if (sr.flag) { cell.textContent = x === 1 ? 'yes' : Number.isFinite(x) ? 'NO' : '–'; cell.className = 'v' + (x === 1 ? '' : ' bad'); }
      else if (Number.isInteger(x)) cell.textContent = String(x);
      else cell.textContent = Number.isFinite(x) ? (Math.abs(x) >= 1e4 || (Math.abs(x) < 1e-3 && x !== 0) ? x.toExponential(3) : x.toFixed(4)) : '–';
    });
    $('clock').textContent = `t = ${time[frame].toFixed(3)} s  (frame ${frame + 1}/${nf})`;
    $('slider').value = frame;
    drawCursors();
    const msg = failed.get(frame) || (posesOk ? '' : `frame ${frame}: no pose (kinematics failed)`);
    $('banner').style.display = msg && showUI ? 'block' : 'none'; $('banner').textContent = msg;
    render();
  }
  function render() { renderer.render(scene, camera); }

  // -- hover: name, force and strength of the path under the pointer ----------------------
  const ray = new THREE.Raycaster(), ndc = new THREE.Vector2();
  function pick(x, y) {  // css px in the canvas -> {name, kind, force, unit, strength} or null
    const rect = canvas.getBoundingClientRect();
    ndc.set((x - rect.left) / rect.width * 2 - 1, -((y - rect.top) / rect.height) * 2 + 1);
    ray.setFromCamera(ndc, camera);
    if (!tubes.visible || !nseg) return null;
    const hit = ray.intersectObject(tubes, false)[0];
    if (!hit) return null;
    const j = segPath[hit.instanceId], p = S.paths[j], f = pathForce[frame * S.paths.length + j];
    return { name: p.name, kind: p.kind, force: Number.isFinite(f) ? f : null, unit: p.kind === 'spring' ? '' : 'N',
      strength: p.strength, strength_unit: p.strength_unit };
  }
  function showTip(x, y) {
    const h = pick(x, y), tip = $('tip');
    if (!h) { tip.style.display = 'none'; return h; }
    const st = h.strength != null ? `; ${h.kind === 'ligament' ? 'stiffness' : 'strength'} ${h.strength.toPrecision(3)} ${h.strength_unit}` : '';
    tip.textContent = `${h.name} (${h.kind}): ${h.force === null ? '–' : h.force.toPrecision(4) + ' ' + h.unit}${st}`;
    tip.style.left = (x + 12) + 'px'; tip.style.top = (y + 12) + 'px'; tip.style.display = 'block';
    return h;
  }
  function hoverParam() {  // tests: what the pointer at x,y (css px) would show (again after a resize)
    if (!params.has('hover')) return;
    const [hx, hy] = params.get('hover').split(',').map(Number);
    say('hover ' + JSON.stringify({ x: hx, y: hy, hit: showTip(hx, hy), tip: $('tip').textContent }));
  }
  canvas.addEventListener('pointermove', (e) => { if (!e.buttons) showTip(e.clientX, e.clientY); });
  canvas.addEventListener('pointerleave', () => { $('tip').style.display = 'none'; });

  // -- playback -----------------------------------------------------------------------
  let playing = false, speed = parseFloat(params.get('speed') || '1'), simTime = 0, last = null;
  $('speed').value = String(speed);
  function frameAt(t) {  // last frame with time <= t
    let lo = 0, hi = nf - 1;
    while (lo < hi) { const mid = (lo + hi + 1) >> 1; if (time[mid] <= t) lo = mid; else hi = mid - 1; }
    return lo;
  }
  function setPlaying(p) { playing = p; $('play').innerHTML = p ? '&#10074;&#10074;' : '&#9654;'; last = null; simTime = time[frame]; }
  function tick(now) {
    if (playing && nf > 1) {
      if (last !== null) {
        simTime += (now - last) / 1000 * speed;
        if (simTime > time[nf - 1]) simTime = time[0];
        const k = frameAt(simTime); if (k !== frame) setFrame(k);
      }
      last = now;
    }
    requestAnimationFrame(tick);
  }
  $('play').addEventListener('click', () => setPlaying(!playing));
  $('slider').max = String(nf - 1);
  $('slider').addEventListener('input', (e) => { setFrame(+e.target.value); simTime = time[frame]; });
  $('speed').addEventListener('change', (e) => { speed = parseFloat(e.target.value); });
  window.addEventListener('keydown', (e) => {
    if (e.target instanceof HTMLInputElement || e.target instanceof HTMLSelectElement) return;
    if (e.code === 'Space') { setPlaying(!playing); e.preventDefault(); }
    if (e.code === 'KeyF') { fit(); e.preventDefault(); }
  });
  $('fit').addEventListener('click', () => fit());
  for (const bt of document.querySelectorAll('[data-view]')) bt.addEventListener('click', () => setView(bt.dataset.view));
  window.addEventListener('resize', () => {
    renderer.setSize(window.innerWidth, window.innerHeight, false);
    if (autoFramed) fit(); else { applyOffset(); render(); }
    say('size ' + window.innerWidth + ' ' + window.innerHeight + ' ' + JSON.stringify(cameraInfo()));
    hoverParam();
  });

  // -- start ------------------------------------------------------------------------------
  let start = 0;
  if (params.has('frame')) start = parseInt(params.get('frame'), 10);
  else if (params.has('t')) {  // nearest frame to t
    const t = parseFloat(params.get('t')), k = frameAt(t);
    start = (k + 1 < nf && Math.abs(time[k + 1] - t) < Math.abs(time[k] - t)) ? k + 1 : k;
  }
  setView(params.get('view') || 'oblique');
  if (params.has('cam')) {
    const c = params.get('cam').split(',').map(Number);
    camera.position.set(c[0], c[1], c[2]); controls.target.set(c[3], c[4], c[5]);
    camera.lookAt(controls.target); controls.update(); autoFramed = false;
  }
  setFrame(start);
  if (params.get('fit') === '1') window.dispatchEvent(new KeyboardEvent('keydown', { code: 'KeyF' }));
  hoverParam();
  if (params.get('play') === '1') setPlaying(true);
  requestAnimationFrame(tick);
  document.body.dataset.status = 'ready';
  say('ready ' + JSON.stringify({ ...cameraInfo(), frame, time: time[frame],
    legend: $('legend').textContent, bodies: nb, meshes: S.meshes.length, markers: nm, paths: S.paths.length, wrapped: S.paths.filter((p) => p.wrap).length, contacts: contacts.length }));
})();
