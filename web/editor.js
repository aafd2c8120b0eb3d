// The editor page of `voxwarp edit`: handles on the model, live results from POST /api/deform, undo/redo,
// edit files in and out. window.voxwarp exposes its state to scripts and to the browser test.
'use strict';

(function () {
  const canvas = document.getElementById('view');
  // No multisampling: with software WebGL (SwiftShader) it costs more than the live result can spare.
  const view = Viewer.create(canvas, canvas.clientWidth || 800, canvas.clientHeight || 600, false);
  const controls = new THREE.OrbitControls(view.camera, canvas);
  // Orthographic view: the perspective camera stays the one the controls move; the orthographic one copies its
  // place and turn, with the view height the perspective one has at the orbit's centre, whenever it is used.
  const ortho = new THREE.OrthographicCamera(-1, 1, 1, -1, 0.01, 1000);
  let orthographic = false;
  function eye() {
    if (!orthographic) return view.camera;
    view.camera.updateMatrixWorld();
    ortho.position.copy(view.camera.position);
    ortho.quaternion.copy(view.camera.quaternion);
    const distance = view.camera.position.distanceTo(controls.target);
    const half = distance * Math.tan(view.camera.fov * Math.PI / 360);
    ortho.top = half; ortho.bottom = -half;
    ortho.left = -half * view.camera.aspect; ortho.right = half * view.camera.aspect;
    ortho.near = view.camera.near; ortho.far = view.camera.far;
    ortho.updateProjectionMatrix();
    ortho.updateMatrixWorld();
    return ortho;
  }
  controls.enableDamping = false;
  let needsRender = true; // frames are drawn when something changed, not continuously
  function redraw() { needsRender = true; }
  controls.addEventListener('change', redraw);
  const status = document.getElementById('status');

  // ---- State: the committed edits, the current one, undo/redo snapshots. --------------------------------------
  const state = { lattice: null, edits: [], current: { solver: 'min-norm', preserve_volume: false, constraints: [] } };
  let selected = -1;
  const undoStack = [], redoStack = [];
  // The shapes edits start from, by the edits before them: what a click picks on after Next edit, undo and redo.
  const sourceCache = new Map();
  let model = null, fullResolution = 128, modelName = 'model';
  let lastFullPly = null, lastReport = null;

  const api = {
    ready: false, resultVersion: 0, lastResolution: 0, requests: 0, errors: [], notes: [],
    drag: { active: false, updates: 0, start: 0, seconds: 0 },
    state: state,
  };
  window.voxwarp = api;

  function snapshot() { return JSON.stringify({ state: state }); }
  function commit() { undoStack.push(lastSnapshot); lastSnapshot = snapshot(); redoStack.length = 0; save(); }
  /// The work so far, kept in the browser for this model: a reload of the page takes it up again.
  let storageKey = null;
  function save() {
    if (!storageKey) return;
    try {
      if (script().edits.length) localStorage.setItem(storageKey, api.editJSON());
      else localStorage.removeItem(storageKey);
    } catch (e) { /* storage full or off: the work is only lost on a reload */ }
  }
  let lastSnapshot = snapshot();
  function restore(text) {
    const s = JSON.parse(text);
    state.lattice = s.state.lattice; state.edits = s.state.edits; state.current = s.state.current;
    selected = -1;
    lastSnapshot = text;
    syncControls(); rebuildHandles(); showSource();
    return requestDeform(fullResolution);
  }

  // ---- The edit script in the edit-file schema. ----------------------------------------------------------------
  // Handles are moves and pins (with their weights); every other entry of a loaded file (control-point offsets,
  // frames, regions, connects, normals, slides) is kept as it came and written back.
  /// A frame's turn {axis, degrees} from its quaternion [x, y, z, w]; null when it does not turn.
  function rotateOf(q) {
    const quaternion = new THREE.Quaternion().fromArray(q).normalize();
    const angle = 2 * Math.acos(Math.min(1, Math.abs(quaternion.w)));
    if (angle < 1e-9) return null;
    const s = Math.sqrt(1 - quaternion.w * quaternion.w) * Math.sign(quaternion.w || 1);
    return { axis: [quaternion.x / s, quaternion.y / s, quaternion.z / s], degrees: angle * 180 / Math.PI };
  }
  function quaternionOf(rotate) {
    if (!rotate) return [0, 0, 0, 1];
    const axis = new THREE.Vector3().fromArray(rotate.axis).normalize();
    return new THREE.Quaternion().setFromAxisAngle(axis, rotate.degrees * Math.PI / 180).toArray();
  }
  function constraintObject(c) {
    if (c.kind === 'raw') return c.entry;
    if (c.entry && JSON.stringify([c.point, c.to, c.turn]) === c.pristine) return c.entry; // a loaded frame as it came
    let out;
    if (c.kind === 'frame') {
      out = { frame: c.point, to: c.to };
      const rotate = rotateOf(c.turn);
      if (rotate) out.rotate = rotate;
    } else if (c.kind === 'region') { // the sphere's motion: about its centre, then to its target
      out = { region: { sphere: [c.point, c.radius] } };
      if (c.to.some((x, i) => x !== c.point[i])) out.translate = c.to.map((x, i) => x - c.point[i]);
      const rotate = rotateOf(c.turn);
      if (rotate) out.rotate = Object.assign(rotate, { pivot: c.point });
    } else {
      out = c.kind === 'pin' ? { pin: c.point } : { move: c.point, to: c.to };
    }
    if (c.weight !== undefined) out.weight = c.weight;
    return out;
  }
  function editObject(e) {
    return { solver: e.solver, preserve_volume: e.preserve_volume, constraints: e.constraints.map(constraintObject) };
  }
  function sourceKey(k) { return JSON.stringify(state.edits.slice(0, k).map(editObject)); }
  function sourceOf(k) { return k === 0 ? model : sourceCache.get(sourceKey(k)); }
  function isSource(g) { return g === model || Array.from(sourceCache.values()).indexOf(g) >= 0; }
  function script() {
    const edits = state.edits.map(editObject);
    if (state.current.constraints.length) edits.push(editObject(state.current));
    const out = { edits: edits };
    if (state.lattice) out.lattice = state.lattice;
    return out;
  }
  api.editJSON = function () { return JSON.stringify(script(), null, 2); };

  // ---- Scene objects. ---------------------------------------------------------------------------------------------
  // The shape the edit starts from (what a click picks on) and the result: one of the two is shown, the result
  // unless Before is on (no translucent ghost over the result: the two surfaces coincide and would z-fight).
  const sourceMesh = new THREE.Mesh(new THREE.BufferGeometry(), Viewer.material(0x9aa0a8));
  const resultMesh = new THREE.Mesh(new THREE.BufferGeometry(), Viewer.material(0xd99a5b));
  // A model with a texture (or vertex colours) is shown with it wherever its geometry carries texture coordinates
  // (or colours): the model, and full results (drag previews carry none, and show in the plain colour).
  const plain = new Map([[sourceMesh, sourceMesh.material], [resultMesh, resultMesh.material]]);
  let texturedMaterial = null, colouredMaterial = null;
  function dress(mesh) {
    const g = mesh.geometry.attributes;
    const material = g.uv && texturedMaterial ? texturedMaterial : g.color && colouredMaterial ? colouredMaterial : plain.get(mesh);
    if (mesh.material !== material) mesh.material = material;
  }
  api.deformAt = resolution => requestDeform(resolution); // for scripts: a result (or a preview, below the full resolution)
  api.dressed = function () {
    const kind = m => (m.material === texturedMaterial ? 'texture' : m.material === colouredMaterial ? 'colours' : 'plain');
    return { source: kind(sourceMesh), result: kind(resultMesh) };
  };
  let before = false;
  view.scene.add(resultMesh); view.scene.add(sourceMesh);
  const handles = new THREE.Group();
  view.scene.add(handles);
  let handleRadius = 0.05;

  function ball(colour, radius) {
    return new THREE.Mesh(new THREE.SphereBufferGeometry(radius, 16, 12), new THREE.MeshStandardMaterial({ color: colour, roughness: 0.4 }));
  }
  function rebuildHandles() {
    showSelected();
    if (dragging) gizmo.detach(); // a target dragged by itself: the gizmo (costly to draw in software) comes back after
    else if (!gizmo.dragging) attachGizmo();
    while (handles.children.length) handles.remove(handles.children[0]);
    state.current.constraints.forEach(function (c, i) {
      if (c.kind === 'raw') return; // kept, not shown
      const pick = i === selected ? 1.35 : 1;
      if (c.kind === 'pin') {
        const b = ball(i === selected ? 0x1d4ed8 : 0x3b82f6, handleRadius * pick);
        b.position.fromArray(c.point); b.userData = { index: i, role: 'pin' };
        handles.add(b);
        return;
      }
      const from = ball(0x6b7280, handleRadius * 0.6);
      from.position.fromArray(c.point); from.userData = { index: i, role: 'point' };
      const to = ball(i === selected ? 0xea580c : 0xf59e0b, handleRadius * pick);
      to.position.fromArray(c.to); to.userData = { index: i, role: 'target' };
      const line = new THREE.Line(new THREE.BufferGeometry().setFromPoints([from.position, to.position]), new THREE.LineBasicMaterial({ color: 0x444444 }));
      handles.add(from); handles.add(to); handles.add(line);
      if (c.kind === 'region') { // the sphere where it goes, turned as it turns
        const sphere = new THREE.Mesh(new THREE.SphereBufferGeometry(c.radius, 24, 16),
          new THREE.MeshBasicMaterial({ color: i === selected ? 0x7c3aed : 0xa78bfa, wireframe: true, transparent: true, opacity: 0.5 }));
        sphere.position.fromArray(c.to);
        sphere.quaternion.fromArray(c.turn);
        sphere.userData = { index: i, role: 'region' };
        handles.add(sphere);
      }
      if (c.kind === 'frame') { // its axes, turned as the frame turns the map there
        const axes = new THREE.AxesHelper(handleRadius * 4);
        axes.position.fromArray(c.to);
        axes.quaternion.fromArray(c.turn);
        handles.add(axes);
      }
    });
    redraw();
  }
  function showSource() {
    sourceMesh.geometry = sourceOf(state.edits.length) || model;
    dress(sourceMesh);
    sourceMesh.visible = before;
    resultMesh.visible = !before;
    document.getElementById('before').checked = before;
    redraw();
  }
  api.visible = function () { return { source: sourceMesh.visible, result: resultMesh.visible }; };
  api.sourceIsModel = function () { return sourceMesh.geometry === model; };
  function syncControls() {
    const lattice = state.lattice || {};
    document.getElementById('lattice-size').value = lattice.size === undefined ? '' : [].concat(lattice.size).join(', ');
    document.getElementById('lattice-placement').value = lattice.placement || 'uniform';
    document.getElementById('lattice-padding').value = lattice.padding === undefined ? '' : lattice.padding;
    document.getElementById('solver').value = state.current.solver;
    document.getElementById('preserve-volume').checked = state.current.preserve_volume;
    document.getElementById('edits').textContent = state.edits.length ? state.edits.length + ' earlier edit(s), this is edit ' + (state.edits.length + 1) : '';
  }

  // ---- Deform requests: at most one preview in flight, the newest state wins; a full-resolution request goes out
  // at once (the server cancels the preview it supersedes) and no queued preview is sent after it.
  let inFlight = false, pending = 0, issued = 0, lastFull = 0;
  function requestDeform(resolution, again = false) {
    if (!script().edits.length) { resultMesh.geometry = model; dress(resultMesh); showSource(); refreshLattice(); return Promise.resolve(true); }
    const full = resolution === fullResolution;
    if (full) { lastFull = ++issued; pending = 0; }
    else if (inFlight) { pending = resolution; return Promise.resolve(true); }
    const id = full ? lastFull : ++issued;
    inFlight = inFlight || !full;
    api.requests++;
    const body = api.editJSON();
    const started = performance.now();
    return Viewer.api('/api/deform?resolution=' + resolution, { method: 'POST', body: body, headers: { 'Content-Type': 'application/json' } })
      .then(async function (response) {
        if (response.status === 409) {
          // Superseded: a newer request is on its way. Unless this is the newest the page sent: the server cancels
          // by arrival, so an older request that overtook it on its way (each goes on a connection of its own) is
          // answered instead, and that answer is dropped below as superseded. Sent again, it is shown; once only,
          // so that two pages on one server cannot cancel each other's requests for ever.
          if (full && id === issued && !again) return requestDeform(fullResolution, true);
          return true;
        }
        if (!response.ok) {
          const e = await response.json().catch(() => ({ error: response.statusText }));
          showError(e.error);
          return false;
        }
        const buffer = await response.arrayBuffer();
        if (id < lastFull || (full && body !== api.editJSON())) return true; // a later full result is coming
        const previous = resultMesh.geometry;
        resultMesh.geometry = Viewer.parsePly(buffer);
        dress(resultMesh);
        if (previous !== resultMesh.geometry && !isSource(previous)) previous.dispose();
        redraw();
        lastReport = JSON.parse(response.headers.get('X-Voxwarp-Report') || '{}');
        if (full) { lastFullPly = buffer; refreshLattice(); }
        api.shownEdit = body;
        api.lastResolution = resolution;
        api.resultVersion++;
        if (api.drag.active) api.drag.updates++;
        showReport(lastReport, resolution, performance.now() - started);
        return true;
      })
      .catch(function (e) { showError(String(e)); return false; })
      .finally(function () {
        if (full) return;
        inFlight = false;
        if (pending) { const r = pending; pending = 0; requestDeform(r); }
      });
  }
  /// A handle that turns asks for a solve that turns the material with it: the least control-point motion shears
  /// a turn instead (the box bent 90 degrees that way gains a third in volume). So an edit whose solver was not
  /// chosen (in the panel or the loaded file) becomes rigid when one of its handles turns, and the status says so.
  function turnedHandle(c) {
    const turned = c && c.turn && Math.abs(c.turn[3]) < 1 - 1e-9;
    if (!turned || state.current.solver !== 'min-norm' || state.current.solverChosen) return;
    state.current.solver = 'rigid';
    state.current.solverTurned = true;
    document.getElementById('solver').value = 'rigid';
    api.notes.push('solver rigid: a handle turns');
  }
  function showError(message) {
    status.className = 'error';
    status.textContent = message;
    api.errors.push(message);
  }
  function showReport(report, resolution, ms) {
    status.className = '';
    status.textContent = 'resolution ' + resolution + ', ' + report.output_faces + ' faces, ' + Math.round(ms) + ' ms\n' +
      (report.volume_change_percent === null ? 'volume: no input volume to compare' // parts wound inside out cancel it
        : 'volume ' + (report.volume_change_percent >= 0 ? '+' : '') + report.volume_change_percent.toFixed(2) + ' %') +
      (state.current.solverTurned && state.current.solver === 'rigid' ? '\nsolver rigid: a handle turns (min-norm would shear it)' : '');
    (report.thin_parts || []).forEach(function (p) { // what the voxmap lost (README, "Reports")
      status.className = 'warning';
      status.textContent += '\n' + (p.stage === 'voxelize' ? 'voxelizing' : p.stage) + ' loses a part ' + p.thickness_voxels.toFixed(2) +
        ' voxel thick near (' + p.centre.map(function (x) { return x.toPrecision(3); }).join(', ') + ')' +
        (p.resolution_to_keep ? '; resolution ' + p.resolution_to_keep + ' keeps it' : '');
    });
    const table = document.getElementById('residuals');
    table.innerHTML = '<tr><td>constraint</td><td>map</td><td>surface</td></tr>';
    const edit = report.edits && report.edits[report.edits.length - 1];
    (edit ? edit.constraints : []).forEach(function (c) {
      const row = table.insertRow();
      row.insertCell().textContent = c.name.replace(/^edits\[\d+\]\./, '') + ' ' + c.kind;
      row.insertCell().textContent = c.residual_voxels.toExponential(1);
      const miss = row.insertCell();
      miss.textContent = c.surface_miss_voxels == null ? '' : c.surface_miss_voxels.toFixed(2) + ' vox';
      if (c.surface_miss_voxels > 0.5) { miss.className = 'bad'; miss.title = c.miss_cause || ''; }
    });
  }

  // ---- Pointer: pick, add, select, drag. ---------------------------------------------------------------------
  const raycaster = new THREE.Raycaster();
  function ndc(event) {
    const r = canvas.getBoundingClientRect();
    return new THREE.Vector2(((event.clientX - r.left) / r.width) * 2 - 1, -((event.clientY - r.top) / r.height) * 2 + 1);
  }
  /// The first hit of the raycaster's ray on the shape the edit starts from, shown or not (three.js skips hidden
  /// objects in intersectObject, so the mesh is asked directly).
  function pickSource() {
    const hits = [];
    sourceMesh.raycast(raycaster, hits);
    hits.sort((a, b) => a.distance - b.distance);
    return hits[0];
  }
  let down = null, dragging = null;
  canvas.addEventListener('pointerdown', function (event) {
    gizmoDragged = false;
    if (event.button !== 0 || gizmo.axis) return; // on the gizmo: it takes the drag
    raycaster.setFromCamera(ndc(event), eye());
    const hit = raycaster.intersectObjects(handles.children.filter(h => h.isMesh))[0];
    down = { x: event.clientX, y: event.clientY, hit: hit };
    if (hit && hit.object.userData.role === 'target') {
      const i = hit.object.userData.index;
      selected = i;
      const normal = view.camera.getWorldDirection(new THREE.Vector3());
      dragging = { index: i, plane: new THREE.Plane().setFromNormalAndCoplanarPoint(normal, hit.object.position), y: event.clientY, moved: false };
      controls.enabled = false;
      api.drag = { active: true, updates: 0, start: performance.now(), seconds: 0 };
      try { canvas.setPointerCapture(event.pointerId); } catch (e) { /* a synthetic pointer has nothing to capture */ }
      showSource(); rebuildHandles();
    }
  });
  canvas.addEventListener('pointermove', function (event) {
    if (!dragging) return;
    const c = state.current.constraints[dragging.index];
    if (event.shiftKey) { // depth: along the view direction, a model-size fraction per pixel
      const dir = view.camera.getWorldDirection(new THREE.Vector3());
      const size = model.boundingSphere.radius;
      const to = new THREE.Vector3().fromArray(c.to).addScaledVector(dir, (event.clientY - dragging.y) * size / 200);
      c.to = to.toArray();
      dragging.plane.setFromNormalAndCoplanarPoint(dir, to);
    } else {
      raycaster.setFromCamera(ndc(event), eye());
      const p = new THREE.Vector3();
      if (!raycaster.ray.intersectPlane(dragging.plane, p)) return;
      c.to = p.toArray();
    }
    dragging.y = event.clientY;
    dragging.moved = true;
    rebuildHandles();
    requestDeform(Math.max(16, Math.round(fullResolution / 2)));
  });
  canvas.addEventListener('pointerup', function (event) {
    if (gizmoDragged || gizmo.dragging) { down = null; return; }
    if (dragging) {
      const moved = dragging.moved;
      dragging = null;
      controls.enabled = true;
      api.drag.active = false;
      api.drag.seconds = (performance.now() - api.drag.start) / 1000;
      showSource();
      if (moved) { commit(); requestDeform(fullResolution); }
      down = null;
      return;
    }
    if (!down || Math.hypot(event.clientX - down.x, event.clientY - down.y) > 4) { down = null; return; } // an orbit
    if (down.hit) { // select a pin or a move's start
      selected = down.hit.object.userData.index;
      rebuildHandles();
      down = null;
      return;
    }
    down = null;
    raycaster.setFromCamera(ndc(event), eye());
    const hit = pickSource();
    if (!hit) return;
    const point = hit.point.toArray();
    const tool = document.querySelector('input[name=tool]:checked').value;
    state.current.constraints.push(tool === 'pin' ? { kind: 'pin', point: point }
      : tool === 'frame' ? { kind: 'frame', point: point, to: point.slice(), turn: [0, 0, 0, 1] }
        : tool === 'region' ? { kind: 'region', point: point, to: point.slice(), turn: [0, 0, 0, 1], radius: +(model.boundingSphere.radius * 0.15).toPrecision(3) }
          : { kind: 'move', point: point, to: point.slice() });
    selected = state.current.constraints.length - 1;
    commit();
    showSource(); rebuildHandles();
    requestDeform(fullResolution);
  });

  // ---- The gizmo on the selected handle's target: move it along an axis or a plane, turn a frame about an axis
  // (three.js TransformControls, from libjs-three), turns snapped to 15 degrees unless Snap is off. --------------
  const gizmoTarget = new THREE.Object3D();
  view.scene.add(gizmoTarget);
  const gizmo = new THREE.TransformControls(view.camera, canvas);
  gizmo.setSpace('world');
  gizmo.setRotationSnap(Math.PI / 12);
  view.scene.add(gizmo);
  let gizmoDragged = false;
  gizmo.addEventListener('change', redraw);
  gizmo.addEventListener('dragging-changed', function (event) {
    controls.enabled = !event.value;
    if (event.value) {
      gizmoDragged = true;
      api.drag = { active: true, updates: 0, start: performance.now(), seconds: 0 };
      return;
    }
    api.drag.active = false;
    api.drag.seconds = (performance.now() - api.drag.start) / 1000;
    commit(); rebuildHandles(); showSource(); requestDeform(fullResolution);
  });
  gizmo.addEventListener('objectChange', function () {
    const c = state.current.constraints[selected];
    if (!c || !c.to) return;
    c.to = gizmoTarget.position.toArray();
    if (c.turn) { c.turn = gizmoTarget.quaternion.toArray(); turnedHandle(c); } // frames and regions turn
    rebuildHandles();
    requestDeform(Math.max(16, Math.round(fullResolution / 2)));
  });
  function attachGizmo() {
    const c = state.current.constraints[selected];
    if (!c || !c.to || c.kind === 'raw') { gizmo.detach(); return; }
    if (gizmo.getMode() === 'rotate' && !c.turn) gizmo.setMode('translate');
    gizmoTarget.position.fromArray(c.to);
    gizmoTarget.quaternion.fromArray(c.turn || [0, 0, 0, 1]);
    gizmoTarget.updateMatrixWorld();
    gizmo.attach(gizmoTarget);
  }
  function gizmoMode(mode) {
    const c = state.current.constraints[selected];
    gizmo.setMode(mode === 'rotate' && !(c && c.turn) ? 'translate' : mode);
    redraw();
  }
  document.getElementById('gizmo-move').onclick = () => gizmoMode('translate');
  document.getElementById('gizmo-turn').onclick = () => gizmoMode('rotate');
  document.getElementById('gizmo-snap').onchange = e => gizmo.setRotationSnap(e.target.checked ? Math.PI / 12 : null);
  /// For scripts and the browser test: the gizmo's state, and the canvas pixels a turn of `degrees` about the
  /// world axis drags between (TransformControls turns by the drag's length across the axis, 20 / distance
  /// radians per world unit of the pointer on the gizmo's plane).
  api.gizmo = () => ({ attached: !!gizmo.object, mode: gizmo.getMode() });
  api.gizmoTurnDrag = function (axis, degrees) {
    view.camera.updateMatrixWorld();
    gizmo.updateMatrixWorld();
    const centre = gizmoTarget.getWorldPosition(new THREE.Vector3());
    const camera = view.camera.position.clone(), distance = centre.distanceTo(camera);
    const eye = camera.clone().sub(centre).normalize();
    const a = new THREE.Vector3().fromArray(axis).normalize();
    const name = ['X', 'Y', 'Z'][[0, 1, 2].reduce((best, i) => (Math.abs(axis[i]) > Math.abs(axis[best]) ? i : best), 0)];
    // A point of the axis' ring where the gizmo itself says the pointer is on that axis (its hover test).
    const radius = distance * gizmo.size / 7; // TransformControlsGizmo: eye distance x size / 7
    const u = new THREE.Vector3(1, 0, 0).cross(a).lengthSq() > 1e-6 ? new THREE.Vector3(1, 0, 0).cross(a).normalize() : new THREE.Vector3(0, 1, 0).cross(a).normalize();
    const v = a.clone().cross(u);
    const r = canvas.getBoundingClientRect();
    let start = null;
    for (let k = 0; k < 72 && !start; ++k) {
      const t = k * Math.PI / 36;
      const p = centre.clone().addScaledVector(u, radius * Math.cos(t)).addScaledVector(v, radius * Math.sin(t));
      const [x, y] = api.screenOf(p.toArray());
      canvas.dispatchEvent(new MouseEvent('mousemove', { clientX: r.left + x, clientY: r.top + y, bubbles: true }));
      if (gizmo.axis === name) start = p;
    }
    if (!start) return null;
    // The pointer's way on the plane facing the camera through the gizmo (the one TransformControls measures on).
    const onPlane = start.clone().sub(camera).multiplyScalar(centre.clone().sub(camera).dot(eye) / start.clone().sub(camera).dot(eye)).add(camera);
    const across = a.clone().cross(eye).normalize();
    const end = onPlane.clone().addScaledVector(across, degrees * Math.PI / 180 * distance / 20);
    return [api.screenOf(start.toArray()), api.screenOf(end.toArray())];
  };

  // ---- The selected handle in numbers: its point, target and (a frame's) turn as Euler angles in degrees. ------
  const numbers = { point: document.getElementById('sel-point'), to: document.getElementById('sel-to'), turn: document.getElementById('sel-turn'),
    radius: document.getElementById('sel-radius') };
  numbers.radius.oninput = function () { // a region's radius, live on the slider
    const c = state.current.constraints[selected];
    if (!c || c.kind !== 'region') return;
    c.radius = Number(numbers.radius.value);
    rebuildHandles();
  };
  numbers.radius.onchange = function () { commit(); requestDeform(fullResolution); };
  const format = a => a.map(x => +x.toFixed(6)).join(', ');
  function showSelected() {
    const c = state.current.constraints[selected];
    const shown = c && c.kind !== 'raw';
    document.getElementById('selected').style.display = shown ? '' : 'none';
    if (!shown) return;
    numbers.point.value = format(c.point);
    numbers.to.value = c.to ? format(c.to) : '';
    numbers.to.disabled = c.kind === 'pin';
    const e = new THREE.Euler().setFromQuaternion(new THREE.Quaternion().fromArray(c.turn || [0, 0, 0, 1]), 'XYZ');
    numbers.turn.value = format([e.x, e.y, e.z].map(r => r * 180 / Math.PI));
    numbers.turn.disabled = !c.turn;
    document.getElementById('radius-row').style.display = c.kind === 'region' ? '' : 'none';
    if (c.kind === 'region') numbers.radius.value = c.radius;
  }
  function parseTriple(text) {
    const v = text.split(/[\s,]+/).filter(x => x.length).map(Number);
    return v.length === 3 && v.every(isFinite) ? v : null;
  }
  function typed(field) {
    return function () {
      const c = state.current.constraints[selected];
      if (!c || !numbers[field].value.trim()) return; // emptied: nothing typed yet
      const v = parseTriple(numbers[field].value);
      if (!v) { showError('expected three numbers, e.g. 1, 0.5, -2'); showSelected(); return; }
      if (field === 'turn') {
        c.turn = new THREE.Quaternion().setFromEuler(new THREE.Euler(...v.map(d => d * Math.PI / 180), 'XYZ')).toArray();
        turnedHandle(c);
      }
      else if (field === 'to') c.to = v;
      else { c.point = v; if (c.kind === 'pin') c.to = v.slice(); }
      commit(); rebuildHandles(); requestDeform(fullResolution);
    };
  }
  for (const field of ['point', 'to', 'turn']) numbers[field].onchange = typed(field);
  api.select = function (i) { selected = i; rebuildHandles(); };

  // ---- Views: front, side, top; the whole model and its handles, or the selected handle. ----------------------
  function viewBox(onlySelected) {
    const box = new THREE.Box3();
    const c = state.current.constraints[selected];
    if (onlySelected && c && c.kind !== 'raw') {
      box.expandByPoint(new THREE.Vector3().fromArray(c.point));
      if (c.to) box.expandByPoint(new THREE.Vector3().fromArray(c.to));
      box.expandByScalar(model.boundingSphere.radius * 0.15);
      return box;
    }
    box.copy(model.boundingBox);
    state.edits.concat([state.current]).forEach(e => e.constraints.forEach(function (k) {
      if (k.point) box.expandByPoint(new THREE.Vector3().fromArray(k.point));
      if (k.to) box.expandByPoint(new THREE.Vector3().fromArray(k.to));
    }));
    return box;
  }
  let viewAngles = [30, 15];
  function look(azimuth, elevation, onlySelected) {
    viewAngles = [azimuth, elevation];
    const centre = Viewer.frame(view, viewBox(onlySelected), azimuth, elevation, view.camera.aspect);
    controls.target.copy(centre);
    controls.update();
    redraw();
  }
  document.getElementById('view-front').onclick = () => look(0, 0);
  document.getElementById('view-side').onclick = () => look(90, 0);
  document.getElementById('view-top').onclick = () => look(0, 89.9);
  document.getElementById('view-all').onclick = () => look(viewAngles[0], viewAngles[1]);
  document.getElementById('view-selected').onclick = () => look(viewAngles[0], viewAngles[1], true);
  api.cameraDirection = () => view.camera.getWorldDirection(new THREE.Vector3()).toArray();
  function setOrthographic(on) {
    orthographic = on;
    document.getElementById('ortho').checked = on;
    gizmo.camera = eye();
    redraw();
  }
  document.getElementById('ortho').onchange = e => setOrthographic(e.target.checked);
  api.setOrthographic = setOrthographic;
  api.orthographic = () => orthographic;

  // ---- The lattice on demand: the current edit's control points as solved (dark) and at rest (light), joined
  // along each axis; fetched from GET /api/lattice after each full result while shown. ---------------------------
  const latticeGroup = new THREE.Group();
  latticeGroup.visible = false;
  view.scene.add(latticeGroup);
  let latticeFacts = null;
  function latticeLines(points, size, colour, opacity) {
    const [nx, ny, nz] = size, at = (i, j, k) => points[i + nx * (j + ny * k)], segments = [];
    for (let k = 0; k < nz; k++)
      for (let j = 0; j < ny; j++)
        for (let i = 0; i < nx; i++) {
          if (i + 1 < nx) segments.push(...at(i, j, k), ...at(i + 1, j, k));
          if (j + 1 < ny) segments.push(...at(i, j, k), ...at(i, j + 1, k));
          if (k + 1 < nz) segments.push(...at(i, j, k), ...at(i, j, k + 1));
        }
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.Float32BufferAttribute(segments, 3));
    return new THREE.LineSegments(geometry, new THREE.LineBasicMaterial({ color: colour, transparent: opacity < 1, opacity: opacity }));
  }
  async function refreshLattice() {
    const shown = document.getElementById('show-lattice').checked;
    latticeGroup.visible = shown && script().edits.length > 0;
    if (!latticeGroup.visible) { redraw(); return; }
    const response = await Viewer.api('/api/lattice');
    if (response.status !== 200) return;
    const data = await response.json();
    latticeGroup.children.slice().forEach(c => { c.geometry.dispose(); latticeGroup.remove(c); });
    latticeGroup.add(latticeLines(data.rest, data.size, 0x8890a0, 0.35));
    latticeGroup.add(latticeLines(data.solved, data.size, 0x2a4d8f, 1));
    latticeFacts = { size: data.size, points: data.solved.length, segments: latticeGroup.children[1].geometry.attributes.position.count / 2, solved: data.solved };
    api.latticeVersion = (api.latticeVersion || 0) + 1;
    redraw();
  }
  document.getElementById('show-lattice').onchange = refreshLattice;
  api.lattice = () => ({ visible: latticeGroup.visible, facts: latticeFacts });

  // ---- Buttons and keys. -------------------------------------------------------------------------------------
  function remove() {
    if (selected < 0 || selected >= state.current.constraints.length) return;
    state.current.constraints.splice(selected, 1);
    selected = -1;
    commit(); rebuildHandles(); showSource(); requestDeform(fullResolution);
  }
  function undo() { if (undoStack.length) { redoStack.push(lastSnapshot); restore(undoStack.pop()); } }
  function redo() { if (redoStack.length) { undoStack.push(lastSnapshot); restore(redoStack.pop()); } }
  document.getElementById('delete').onclick = remove;
  document.getElementById('undo').onclick = undo;
  document.getElementById('redo').onclick = redo;
  document.getElementById('solver').onchange = function (e) {
    state.current.solver = e.target.value; state.current.solverChosen = true; commit(); requestDeform(fullResolution);
  };
  document.getElementById('preserve-volume').onchange = function (e) { state.current.preserve_volume = e.target.checked; commit(); requestDeform(fullResolution); };
  function toggleBefore() { before = !before; showSource(); }
  /// The lattice's settings from the panel (empty fields: the defaults); the server checks their ranges.
  function latticeChanged() {
    const lattice = {};
    const size = document.getElementById('lattice-size').value.split(/[\s,]+/).filter(x => x.length).map(Number);
    if (size.length === 1) lattice.size = size[0];
    else if (size.length === 3) lattice.size = size;
    else if (size.length) { showError('lattice: expected n or nx, ny, nz'); syncControls(); return; }
    const placement = document.getElementById('lattice-placement').value;
    if (placement !== 'uniform' || (state.lattice && state.lattice.placement)) lattice.placement = placement;
    const padding = document.getElementById('lattice-padding').value.trim();
    if (padding.length) lattice.padding = Number(padding);
    state.lattice = Object.keys(lattice).length ? lattice : null;
    commit(); requestDeform(fullResolution);
  }
  for (const id of ['lattice-size', 'lattice-placement', 'lattice-padding']) document.getElementById(id).onchange = latticeChanged;
  document.getElementById('before').onchange = toggleBefore;
  window.addEventListener('keydown', function (e) {
    if (e.target.tagName === 'SELECT' || e.target.tagName === 'INPUT') return;
    if (e.key === 'Delete' || e.key === 'Backspace') { remove(); e.preventDefault(); }
    else if ((e.ctrlKey || e.metaKey) && e.key === 'z' && !e.shiftKey) { undo(); e.preventDefault(); }
    else if ((e.ctrlKey || e.metaKey) && (e.key === 'y' || (e.key === 'z' && e.shiftKey))) { redo(); e.preventDefault(); }
    else if (e.key === 'b' && !e.ctrlKey && !e.metaKey) { toggleBefore(); e.preventDefault(); }
    else if (e.key === 'g' && !e.ctrlKey && !e.metaKey) { gizmoMode('translate'); e.preventDefault(); }
    else if (e.key === 'r' && !e.ctrlKey && !e.metaKey) { gizmoMode('rotate'); e.preventDefault(); }
    else if (e.key === 'o' && !e.ctrlKey && !e.metaKey) { setOrthographic(!orthographic); e.preventDefault(); }
    else if (e.key === 'l' && !e.ctrlKey && !e.metaKey) {
      const box = document.getElementById('show-lattice');
      box.checked = !box.checked; refreshLattice(); e.preventDefault();
    }
  });
  document.getElementById('next-edit').onclick = async function () {
    if (!state.current.constraints.length) return;
    await requestDeform(fullResolution);
    if (!lastFullPly) return;
    const result = Viewer.parsePly(lastFullPly);
    state.edits.push(state.current);
    sourceCache.set(sourceKey(state.edits.length), result);
    state.current = { solver: state.current.solver, preserve_volume: state.current.preserve_volume, constraints: [] };
    selected = -1;
    commit(); syncControls(); rebuildHandles(); showSource();
  };
  function download(name, blob) {
    const a = document.createElement('a');
    a.href = URL.createObjectURL(blob); a.download = name;
    document.body.appendChild(a); a.click(); a.remove();
  }
  document.getElementById('save-edit').onclick = function () { download('edit.json', new Blob([api.editJSON() + '\n'], { type: 'application/json' })); };
  document.getElementById('save-mesh').onclick = function () {
    if (lastFullPly) download(modelName.replace(/\.[^.]*$/, '') + '_edited.ply', new Blob([lastFullPly], { type: 'application/ply' }));
  };
  document.getElementById('load-edit').onchange = async function (e) {
    const file = e.target.files[0];
    if (file) await api.loadEdit(await file.text(), file.name);
    e.target.value = '';
  };

  /// A point of an edit file: an array of three finite numbers.
  function isPoint(p) { return Array.isArray(p) && p.length === 3 && p.every(x => typeof x === 'number' && isFinite(x)); }
  /// Why an edit file's structure cannot be the editor's state (the server checks the rest), or ''.
  function malformed(data) {
    if (!data || typeof data !== 'object' || !Array.isArray(data.edits) || !data.edits.length) return 'expected {"edits": [...]} with at least one edit';
    for (let k = 0; k < data.edits.length; ++k) {
      const e = data.edits[k], path = 'edits[' + k + ']';
      if (!e || !Array.isArray(e.constraints) || !e.constraints.length) return path + '.constraints: expected a non-empty array';
      for (let j = 0; j < e.constraints.length; ++j) {
        const c = e.constraints[j], where = path + '.constraints[' + j + ']';
        if (!c || typeof c !== 'object') return where + ': expected an object';
        for (const key of ['move', 'to', 'pin', 'frame'])
          if (key in c && !isPoint(c[key])) return where + '.' + key + ': expected an array of three finite numbers';
        if ('move' in c && !('to' in c)) return where + ': missing field "to"';
      }
    }
    return '';
  }
  /// The model and every handle's point and target: what a loaded edit should show.
  function reframe() { look(viewAngles[0], viewAngles[1]); }

  /// Take an edit file's text as the editor's state: its earlier edits' results are computed in turn, so that
  /// the last edit's handles sit on the shape it starts from. A file that is malformed, or that the server
  /// refuses, leaves the state as it was, and the message names the file.
  api.loadEdit = async function (text, name) {
    name = name || 'edit file';
    let data;
    try { data = JSON.parse(text); } catch (e) { showError(name + ': not valid JSON: ' + e.message); return false; }
    const why = malformed(data);
    if (why) { showError(name + ': ' + why); return false; }
    // A move or pin with nothing else than its fields becomes a handle; anything else goes to the server as it came.
    const only = (c, keys) => Object.keys(c).every(k => keys.indexOf(k) >= 0);
    const weight = c => ('weight' in c ? { weight: c.weight } : {});
    const turnable = c => !c.rotate || (isPoint(c.rotate.axis) && isFinite(c.rotate.degrees)); // no turn, or one the page can show
    const toConstraint = c => c.pin && only(c, ['pin', 'weight']) ? Object.assign({ kind: 'pin', point: c.pin }, weight(c))
      : c.move && only(c, ['move', 'to', 'weight']) ? Object.assign({ kind: 'move', point: c.move, to: c.to }, weight(c))
        : c.frame && isPoint(c.frame) && only(c, ['frame', 'to', 'rotate', 'weight']) && turnable(c)
          ? loadedFrame(Object.assign({ kind: 'frame', point: c.frame, to: c.to || c.frame.slice(), turn: quaternionOf(c.rotate) }, weight(c)), c)
          : c.region && c.region.sphere && isPoint(c.region.sphere[0]) && c.region.sphere[1] > 0 && only(c, ['region', 'translate', 'rotate', 'weight'])
            && (!c.translate || isPoint(c.translate)) && turnable(c)
            ? loadedFrame(loadedRegion(c), c)
            : { kind: 'raw', entry: c };
    const loadedRegion = function (c) { // the motion about the pivot, as a turn about the centre and a target for it
      const centre = new THREE.Vector3().fromArray(c.region.sphere[0]);
      const turn = new THREE.Quaternion().fromArray(quaternionOf(c.rotate));
      const pivot = c.rotate && c.rotate.pivot ? new THREE.Vector3().fromArray(c.rotate.pivot) : centre.clone();
      const to = centre.clone().sub(pivot).applyQuaternion(turn).add(pivot).add(new THREE.Vector3().fromArray(c.translate || [0, 0, 0]));
      return Object.assign({ kind: 'region', point: c.region.sphere[0], to: to.toArray(), turn: turn.toArray(), radius: c.region.sphere[1] }, weight(c));
    };
    const loadedFrame = function (handle, entry) {
      handle.entry = entry;
      handle.pristine = JSON.stringify([handle.point, handle.to, handle.turn]);
      return handle;
    };
    const toEdit = e => ({ solver: e.solver || 'min-norm', solverChosen: !!e.solver, preserve_volume: !!e.preserve_volume, constraints: e.constraints.map(toConstraint) });
    const previous = lastSnapshot;
    const fail = async function () { // the page as it was, then the message (after the result it shows again)
      const message = api.errors[api.errors.length - 1] || 'refused';
      await restore(previous);
      showError(message.replace(/^request: /, name + ': '));
      return false;
    };
    state.lattice = data.lattice || null;
    state.edits = [];
    const all = data.edits.map(toEdit);
    for (let k = 0; k + 1 < all.length; ++k) { // the shape each later edit starts from
      state.current = all[k];
      if (!(await requestDeform(fullResolution)) || !lastFullPly) return fail();
      const result = Viewer.parsePly(lastFullPly);
      state.edits.push(all[k]);
      sourceCache.set(sourceKey(state.edits.length), result);
    }
    state.current = all[all.length - 1];
    selected = -1;
    syncControls(); rebuildHandles(); showSource(); reframe();
    if (!(await requestDeform(fullResolution))) return fail();
    commit();
    return true;
  };

  // ---- Tests and scripts. ------------------------------------------------------------------------------------
  /// Canvas pixel (relative to the canvas' top-left) of a world point.
  api.screenOf = function (p) {
    view.camera.updateMatrixWorld(); // a view just set is drawn only at the next frame
    const v = new THREE.Vector3().fromArray(p).project(eye());
    const r = canvas.getBoundingClientRect();
    return [(v.x + 1) / 2 * r.width, (1 - v.y) / 2 * r.height];
  };
  /// The model point under canvas pixel (x, y), or null.
  api.pick = function (x, y) {
    const r = canvas.getBoundingClientRect();
    raycaster.setFromCamera(new THREE.Vector2(x / r.width * 2 - 1, -(y / r.height) * 2 + 1), eye());
    const hit = pickSource();
    return hit ? hit.point.toArray() : null;
  };
  api.lastPlyBase64 = function () {
    if (!lastFullPly) return null;
    const bytes = new Uint8Array(lastFullPly);
    let s = '';
    for (let i = 0; i < bytes.length; i += 0x8000) s += String.fromCharCode.apply(null, bytes.subarray(i, i + 0x8000));
    return btoa(s);
  };
  api.report = function () { return lastReport; };

  // ---- Start. ------------------------------------------------------------------------------------------------
  function resize() {
    const w = canvas.clientWidth, h = canvas.clientHeight;
    view.renderer.setSize(w, h, false);
    view.camera.aspect = w / h;
    view.camera.updateProjectionMatrix();
    redraw();
  }
  window.addEventListener('resize', resize);
  function frame() {
    requestAnimationFrame(frame);
    if (!needsRender) return;
    needsRender = false;
    view.lights[0].position.copy(view.camera.position).multiplyScalar(1.5);
    const t = performance.now();
    gizmo.camera = eye();
    view.renderer.render(view.scene, gizmo.camera);
    view.renderer.getContext().finish();
    api.frames = (api.frames || 0) + 1;
    api.renderMs = performance.now() - t;
  }
  (async function start() {
    const response = await Viewer.api('/api/model');
    if (!response.ok) {
      const e = await response.json().catch(() => ({ error: response.statusText }));
      throw new Error(e.error + (response.status === 403 ? ': open the address that voxwarp edit printed, with its ?token=' : ''));
    }
    const facts = JSON.parse(response.headers.get('X-Voxwarp-Model') || '{}');
    fullResolution = facts.resolution || 128;
    modelName = facts.name || 'model';
    document.getElementById('model-name').textContent = modelName;
    model = Viewer.parsePly(await response.arrayBuffer());
    if (facts.texture && model.attributes.uv) texturedMaterial = Viewer.material(0xffffff, { map: await Viewer.texture('/api/texture') });
    if (model.attributes.color) colouredMaterial = Viewer.material(0xffffff, { vertexColors: true });
    resultMesh.geometry = model;
    dress(resultMesh);
    handleRadius = model.boundingSphere.radius * 0.025;
    numbers.radius.min = (model.boundingSphere.radius * 0.02).toPrecision(3);
    numbers.radius.max = (model.boundingSphere.radius * 0.8).toPrecision(3);
    numbers.radius.step = (model.boundingSphere.radius * 0.005).toPrecision(3);
    resize();
    look(viewAngles[0], viewAngles[1]); // no handles yet: the model's box
    syncControls(); showSource();
    status.textContent = modelName + ': ' + facts.vertices + ' vertices, ' + facts.faces + ' faces; full result at resolution ' + fullResolution;
    frame();
    storageKey = 'voxwarp edit: ' + modelName + ' ' + facts.vertices + ' ' + facts.faces;
    const initial = await Viewer.api('/api/edit');
    const saved = (function () { try { return localStorage.getItem(storageKey); } catch (e) { return null; } })();
    if (initial.status === 200) await api.loadEdit(await initial.text(), 'the edit file given to voxwarp edit');
    else if (saved) await api.loadEdit(saved, 'the work saved in this browser');
    api.ready = true;
  })().catch(e => showError('loading the model failed: ' + e));
})();
