// Shared by the editor (index.html) and the renderer (render.html): three.js scene, lights, binary PLY meshes.
// Served by `voxwarp edit` and `voxwarp render` from the machine (three.js from Debian's libjs-three).
'use strict';

const Viewer = {};

/// fetch() of the server's API with the session token: the server printed the page's URL with ?token=..., and
/// refuses /api/ requests that do not carry it back (a page of another site cannot read it).
Viewer.token = new URLSearchParams(window.location.search).get('token') || '';
Viewer.api = function (path, init) {
  init = Object.assign({}, init || {});
  init.headers = Object.assign({ 'X-Voxwarp-Token': Viewer.token }, init.headers || {});
  return fetch(path, init);
};

/// A texture from the server's API as a three.js texture: fetched with the token (an <img> could not send it), then
/// handed to three.js as an object URL.
Viewer.texture = async function (path) {
  const url = URL.createObjectURL(await (await Viewer.api(path)).blob());
  return new Promise((resolve, reject) => new THREE.TextureLoader().load(url, resolve, undefined, reject));
};

/// Binary little-endian PLY as voxwarp writes it (float x y z, optionally float s t and uchar red green blue, then
/// faces as a uchar count and int indices; polygons are fanned) into a BufferGeometry, with a uv attribute and
/// vertex colours when the file has them.
Viewer.parsePly = function (buffer) {
  const bytes = new Uint8Array(buffer);
  let end = 0;
  const marker = 'end_header\n';
  for (let i = 0; i + marker.length <= bytes.length && i < 65536; ++i) {
    let match = true;
    for (let j = 0; j < marker.length && match; ++j) match = bytes[i + j] === marker.charCodeAt(j);
    if (match) { end = i + marker.length; break; }
  }
  if (!end) throw new Error('not a PLY file');
  const header = new TextDecoder().decode(bytes.subarray(0, end));
  if (!/format binary_little_endian/.test(header)) throw new Error('expected binary little-endian PLY');
  const nv = parseInt(/element vertex (\d+)/.exec(header)[1], 10);
  const nf = parseInt(/element face (\d+)/.exec(header)[1], 10);
  // The vertex properties, in order, with their byte offsets.
  const vertexPart = header.slice(header.indexOf('element vertex'), header.indexOf('element face'));
  const offsets = {};
  let stride = 0;
  for (const m of vertexPart.matchAll(/property (float|uchar) (\w+)/g)) {
    offsets[m[2]] = { at: stride, type: m[1] };
    stride += m[1] === 'float' ? 4 : 1;
  }
  const view = new DataView(buffer, end);
  const positions = new Float32Array(3 * nv);
  const uvs = 's' in offsets && 't' in offsets ? new Float32Array(2 * nv) : null;
  const colours = 'red' in offsets ? new Float32Array(3 * nv) : null;
  for (let i = 0; i < nv; ++i) {
    const base = stride * i;
    for (let a = 0; a < 3; ++a) positions[3 * i + a] = view.getFloat32(base + offsets['xyz'[a]].at, true);
    if (uvs) { uvs[2 * i] = view.getFloat32(base + offsets.s.at, true); uvs[2 * i + 1] = view.getFloat32(base + offsets.t.at, true); }
    if (colours) ['red', 'green', 'blue'].forEach((c, a) => { colours[3 * i + a] = view.getUint8(base + offsets[c].at) / 255; });
  }
  const indices = [];
  let at = stride * nv;
  for (let f = 0; f < nf; ++f) {
    const n = view.getUint8(at); at += 1;
    const first = view.getInt32(at, true);
    let prev = view.getInt32(at + 4, true);
    for (let c = 2; c < n; ++c) {
      const next = view.getInt32(at + 4 * c, true);
      indices.push(first, prev, next);
      prev = next;
    }
    at += 4 * n;
  }
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.BufferAttribute(positions, 3));
  if (uvs) geometry.setAttribute('uv', new THREE.BufferAttribute(uvs, 2));
  if (colours) geometry.setAttribute('color', new THREE.BufferAttribute(colours, 3));
  geometry.setIndex(nv > 65535 ? new THREE.Uint32BufferAttribute(indices, 1) : new THREE.Uint16BufferAttribute(indices, 1));
  geometry.computeVertexNormals();
  geometry.computeBoundingBox();
  geometry.computeBoundingSphere();
  return geometry;
};

/// A renderer, a scene with soft lighting, and a perspective camera.
Viewer.create = function (canvas, width, height, antialias) {
  const renderer = new THREE.WebGLRenderer({ canvas: canvas, antialias: antialias !== false, preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.setSize(width, height, false);
  renderer.setClearColor(0xf4f4f2, 1);
  const scene = new THREE.Scene();
  scene.add(new THREE.HemisphereLight(0xffffff, 0x606070, 0.75));
  const key = new THREE.DirectionalLight(0xffffff, 0.65);
  key.position.set(1, 2, 1.5);
  scene.add(key);
  const fill = new THREE.DirectionalLight(0xffffff, 0.25);
  fill.position.set(-1.5, -0.5, -1);
  scene.add(fill);
  const camera = new THREE.PerspectiveCamera(30, width / height, 0.01, 1000);
  return { renderer: renderer, scene: scene, camera: camera, lights: [key, fill] };
};

Viewer.material = function (color, options) {
  return new THREE.MeshStandardMaterial(Object.assign({ color: color, roughness: 0.6, metalness: 0.0, side: THREE.DoubleSide }, options || {}));
};

/// Flat shading for coarse meshes (a 12-triangle box must not look rounded), smooth for fine ones.
Viewer.materialFor = function (geometry, color, options) {
  const triangles = geometry.index ? geometry.index.count / 3 : geometry.attributes.position.count / 3;
  return Viewer.material(color, Object.assign({ flatShading: triangles < 20000 }, options || {}));
};

/// Put the camera at azimuth / elevation (degrees, azimuth about +y from +z) looking at the box's centre, far
/// enough that the box's bounding sphere fills the view. Lights follow the camera.
Viewer.frame = function (view, box, azimuth, elevation, aspect) {
  const centre = box.getCenter(new THREE.Vector3());
  const radius = Math.max(1e-9, box.getSize(new THREE.Vector3()).length() / 2);
  const a = THREE.MathUtils ? THREE.MathUtils.degToRad(azimuth) : azimuth * Math.PI / 180;
  const e = elevation * Math.PI / 180;
  const dir = new THREE.Vector3(Math.sin(a) * Math.cos(e), Math.sin(e), Math.cos(a) * Math.cos(e));
  const fov = view.camera.fov * Math.PI / 180;
  const distance = radius / Math.sin(Math.min(fov / 2, Math.atan(Math.tan(fov / 2) * aspect))) * 1.05;
  view.camera.aspect = aspect;
  view.camera.position.copy(centre).addScaledVector(dir, distance);
  view.camera.near = distance / 100;
  view.camera.far = distance * 10;
  view.camera.lookAt(centre);
  view.camera.updateProjectionMatrix();
  return centre;
};
