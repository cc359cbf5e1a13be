// The selected clip's skinned mesh, or the character's the motion plays on,
// drawn on the GPU (WebGL2) on a canvas under the 2D one, which keeps the
// skeleton as an overlay.
//
// The mesh comes from GET /v1/clips/{id}/mesh or /v1/characters/{id}/mesh
// (docs/mesh-format.md: a JSON
// header and little-endian arrays, read here as typed-array views). Each
// pose the page shows gives every joint's model matrix M_j (as sent for
// `space=model`, else composed down the hierarchy); the joint palette's
// skinning matrices M_j · invBind_j go to the GPU as a float texture (four
// texels a joint, no uniform limit), and the vertex shader blends them:
// v = Σ w_k · M_jk · invBind_jk · v̂. Lit by a directional light plus
// ambient, coloured by the base colour texture or factor; flat-shaded from
// screen derivatives when the mesh has no normals (as glTF asks). The camera
// is the 2D view's own (math.js cameraBasis, drawn by scene.js), so mesh and
// skeleton line up.

import { authHeaders } from "./api.js";
import { setStatus } from "./dom.js";
import { emit, on } from "./events.js";
import { mat4Multiply as multiply, trs, viewProjection } from "./math.js";
import { state } from "./state.js";

const BACKGROUND = [0x10 / 255, 0x12 / 255, 0x16 / 255];

export const mesh = {
  clip: null, // the clip whose mesh is loaded, or whose motion plays on the character's (null: none)
  character: null, // the character whose mesh is loaded (null: the clip's own, or none)
  info: null, // { vertices, triangles, joints, textured, normals } (read by the browser test)
  draws: 0, // frames drawn with the mesh
  showMesh: true,
  showSkeleton: true,
  poseSpace: null, // the space of the last pose skinned (read by the browser test)
};

let gl = null, programs = null, gpu = null; // the context, its programs, the loaded mesh's buffers
let palette = null; // per palette entry: the pose joint it follows (index), and its inverse bind
let skinning = null; // Float32Array, 16 floats per palette joint (column-major)
let loading = 0; // the latest select() call: an older answer is dropped
let canvas = null, toggles = null; // made by setup()

// ---- the page's controls: a GL canvas under #scene and two toggles ----

/// The canvas and toggles, and the mesh following the page's clip and poses.
export function setup() {
  canvas = document.createElement("canvas");
  canvas.id = "mesh-gl";
  canvas.setAttribute("aria-hidden", "true");
  canvas.hidden = true;
  document.getElementById("scene-view").prepend(canvas);

  // The toggles sit in the view's corner, over the canvases.
  toggles = document.createElement("div");
  toggles.className = "mesh-toggles";
  toggles.hidden = true;
  document.getElementById("scene-view").append(toggles);
  toggle("show-mesh", "mesh", "showMesh");
  toggle("show-skeleton", "skeleton", "showSkeleton");

  on("clipSelected", (clip) => select(clip.id));
  on("clipAdopted", (clip) => state.character || select(clip.id, true)); // a crossfade's clip brings its own mesh
  on("characterChanged", () => state.clip && select(state.clip.id));
  on("pose", (pose) => posed(pose, state.parents));
}

function toggle(id, label, key) {
  const wrap = document.createElement("label");
  const box = document.createElement("input");
  box.type = "checkbox";
  box.id = id;
  box.checked = true;
  box.addEventListener("change", () => {
    mesh[key] = box.checked;
    emit("redraw");
  });
  wrap.append(box, ` ${label}`);
  toggles.append(wrap);
}

function setActive(active) {
  canvas.hidden = !active;
  toggles.hidden = !active;
  document.getElementById("scene-view").classList.toggle("with-mesh", active);
}

// ---- the binary form (docs/mesh-format.md) ----

/// The header and typed-array views of the arrays (no copies).
function parseMesh(buffer) {
  const head = new DataView(buffer, 0, 12);
  const magic = String.fromCharCode(...new Uint8Array(buffer, 0, 4));
  if (magic !== "INBM" || head.getUint32(4, true) !== 1) throw new Error("not an inbetween mesh (INBM version 1)");
  const length = head.getUint32(8, true);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 12, length)));
  const body = 12 + length;
  const TYPES = { f32: Float32Array, u8: Uint8Array, u16: Uint16Array, u32: Uint32Array };
  const view = (a) => a && new TYPES[a.type](buffer, body + a.offset, a.length / TYPES[a.type].BYTES_PER_ELEMENT);
  const arrays = Object.fromEntries(Object.entries(header.arrays).map(([name, a]) => [name, view(a)]));
  const textures = header.textures.map((t) => new Blob([new Uint8Array(buffer, body + t.offset, t.length)], { type: t.mime_type }));
  return { header, arrays, textures };
}

/// Loads the clip's mesh, or the character's (or learns it has none), as a clip or character is selected. Never fails the selection: a mesh that cannot be
/// shown leaves the skeleton view, and the status says why.
const select = (clipId, sameSkeleton = false) => load(clipId, sameSkeleton).catch((e) => setStatus(`mesh not shown: ${e.message}`, true));

function unload() {
  mesh.clip = null;
  mesh.character = null;
  mesh.info = null;
  palette = null;
  setActive(false);
}

async function load(clipId, sameSkeleton) {
  const ticket = ++loading;
  // A crossfade's clip has the same skeleton (the server refuses others),
  // so the old mesh may stay drawn until the answer, and usually it is the
  // same mesh (clips of one skin share it: the browser revalidates, 304).
  if (!sameSkeleton) unload();
  const character = state.character?.id ?? null;
  const owner = character ? `characters/${encodeURIComponent(character)}` : `clips/${encodeURIComponent(clipId)}`;
  const response = await fetch(`/v1/${owner}/mesh`, { headers: authHeaders() });
  if (ticket !== loading) return;
  if (!response.ok) unload();
  if (response.status === 404) return; // no mesh (JSON, BVH, unskinned glTF): the skeleton view
  if (!response.ok) throw new Error(`GET …/mesh answered HTTP ${response.status}`);
  const parsed = parseMesh(await response.arrayBuffer());
  if (ticket !== loading || !context()) return;
  const images = await Promise.all(parsed.textures.map((blob) => createImageBitmap(blob).catch(() => null)));
  if (ticket !== loading) return;
  upload(parsed, images);
  mesh.clip = clipId;
  mesh.character = character;
  const { header, arrays } = parsed;
  mesh.info = {
    vertices: header.vertices,
    triangles: arrays.indices.length / 3,
    joints: header.joints.length,
    textured: images.some(Boolean),
    normals: Boolean(arrays.normal),
  };
  setActive(true);
  bindPose();
  emit("redraw");
}

// ---- poses → skinning matrices ----

/// Every joint's model matrix: as sent in model space, else M_parent · TRS.
function modelMatrices(pose, parents) {
  const out = [];
  pose.joints.forEach((j, i) => {
    const local = trs(j.translation, j.rotation, j.scale);
    const p = parents[i];
    out.push(pose.space === "model" || p < 0 || p >= i ? local : multiply(out[p], local));
  });
  return out;
}

let lastPose = null, lastParents = null, boundNames = null;

/// With each pose the page shows (the `pose` event).
function posed(pose, parents) {
  lastPose = pose;
  mesh.poseSpace = pose.space; // read by the browser test
  lastParents = parents;
  if (gpu) bindPose();
}

/// Skins the last pose, first finding the palette's joints in it by name
/// whenever its joints change (a new clip, a new stream).
function bindPose() {
  if (!lastPose || !gpu) return;
  const names = lastPose.joints.map((j) => j.name).join("\n");
  if (!palette || names !== boundNames) {
    const index = new Map(lastPose.joints.map((j, i) => [j.name, i]));
    palette = gpu.joints.map((name) => index.get(name) ?? -1);
    boundNames = names;
  }
  skin(lastPose, lastParents);
}

function skin(pose, parents) {
  const model = modelMatrices(pose, parents);
  palette.forEach((joint, k) => {
    const m = joint >= 0 ? multiply(model[joint], gpu.inverseBinds[k]) : gpu.inverseBinds[k].map((_, i) => (i % 5 === 0 ? 1 : 0));
    skinning.set(m, 16 * k);
  });
  gpu.posed = true;
}

// ---- WebGL2 ----

const SKIN_VS = `#version 300 es
  in vec3 aPosition; in vec3 aNormal; in vec2 aUv; in uvec4 aJoints; in vec4 aWeights;
  uniform mat4 uViewProjection;
  uniform highp sampler2D uSkinning;
  out vec3 vWorld; out vec3 vNormal; out vec2 vUv;
  mat4 joint(uint j) {
    int row = int(j);
    return mat4(texelFetch(uSkinning, ivec2(0, row), 0), texelFetch(uSkinning, ivec2(1, row), 0),
                texelFetch(uSkinning, ivec2(2, row), 0), texelFetch(uSkinning, ivec2(3, row), 0));
  }
  void main() {
    float total = dot(aWeights, vec4(1.0));
    vec4 w = total > 0.0 ? aWeights / total : vec4(1.0, 0.0, 0.0, 0.0);
    mat4 m = w.x * joint(aJoints.x) + w.y * joint(aJoints.y) + w.z * joint(aJoints.z) + w.w * joint(aJoints.w);
    vec4 world = m * vec4(aPosition, 1.0);
    vWorld = world.xyz;
    vNormal = mat3(m) * aNormal;
    vUv = aUv;
    gl_Position = uViewProjection * world;
  }`;

const SKIN_FS = `#version 300 es
  precision highp float;
  in vec3 vWorld; in vec3 vNormal; in vec2 vUv;
  uniform vec4 uBaseColor; uniform bool uTextured; uniform sampler2D uTexture;
  uniform bool uNormals; uniform vec3 uLight; uniform vec3 uEye;
  out vec4 color;
  void main() {
    vec3 n = uNormals ? normalize(vNormal) : normalize(cross(dFdx(vWorld), dFdy(vWorld)));
    if (dot(n, uEye - vWorld) < 0.0) n = -n;
    vec4 base = uBaseColor * (uTextured ? texture(uTexture, vUv) : vec4(1.0));
    float light = 0.35 + 0.65 * max(dot(n, uLight), 0.0);
    color = vec4(base.rgb * light, 1.0);
  }`;

/// The mesh's depth, packed into RGBA8 (WebGL2 cannot read a depth buffer back).
const DEPTH_FS = `#version 300 es
  precision highp float;
  out vec4 color;
  void main() {
    vec4 e = fract(gl_FragCoord.z * vec4(1.0, 255.0, 65025.0, 16581375.0));
    color = e - e.yzww * vec4(1.0 / 255.0, 1.0 / 255.0, 1.0 / 255.0, 0.0);
  }`;

const LINE_VS = `#version 300 es
  in vec3 aPosition; uniform mat4 uViewProjection;
  void main() { gl_Position = uViewProjection * vec4(aPosition, 1.0); }`;

const LINE_FS = `#version 300 es
  precision mediump float; uniform vec4 uColor; out vec4 color;
  void main() { color = uColor; }`;

/// A program; `locations` (attribute → location) makes it share another's vertex arrays.
function compile(vs, fs, locations = {}) {
  const program = gl.createProgram();
  for (const [name, location] of Object.entries(locations)) if (location >= 0) gl.bindAttribLocation(program, location, name);
  for (const [type, source] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
    const shader = gl.createShader(type);
    gl.shaderSource(shader, source);
    gl.compileShader(shader);
    if (!gl.getShaderParameter(shader, gl.COMPILE_STATUS)) throw new Error(`shader: ${gl.getShaderInfoLog(shader)}`);
    gl.attachShader(program, shader);
  }
  gl.linkProgram(program);
  if (!gl.getProgramParameter(program, gl.LINK_STATUS)) throw new Error(`program: ${gl.getProgramInfoLog(program)}`);
  const uniforms = {};
  for (let i = 0; i < gl.getProgramParameter(program, gl.ACTIVE_UNIFORMS); i++) {
    const name = gl.getActiveUniform(program, i).name;
    uniforms[name] = gl.getUniformLocation(program, name);
  }
  return { program, uniforms, attribute: (name) => gl.getAttribLocation(program, name) };
}

/// The WebGL2 context and programs, made once; `null` without WebGL2
/// (the page then keeps the skeleton view and says why).
function context() {
  if (gl) return gl;
  gl = canvas.getContext("webgl2", { antialias: true });
  if (!gl) {
    setStatus("this browser has no WebGL2: showing the skeleton only", true);
    return null;
  }
  programs = { skin: compile(SKIN_VS, SKIN_FS), line: compile(LINE_VS, LINE_FS) };
  const skin = programs.skin;
  const names = ["aPosition", "aNormal", "aUv", "aJoints", "aWeights"];
  programs.depth = compile(SKIN_VS, DEPTH_FS, Object.fromEntries(names.map((n) => [n, skin.attribute(n)])));
  programs.lineBuffer = gl.createBuffer();
  return gl;
}

/// The mesh's arrays into GPU buffers, its textures, and the skinning texture.
function upload({ header, arrays }, images) {
  if (gpu) {
    gpu.buffers.forEach((b) => gl.deleteBuffer(b));
    gpu.textures.forEach((t) => t && gl.deleteTexture(t));
    gl.deleteTexture(gpu.skinning);
    gl.deleteVertexArray(gpu.vao);
  }
  const s = programs.skin;
  const vao = gl.createVertexArray();
  gl.bindVertexArray(vao);
  const buffers = [];
  const attribute = (name, data, size, integer) => {
    const location = s.attribute(name);
    if (!data || location < 0) return;
    const buffer = gl.createBuffer();
    buffers.push(buffer);
    gl.bindBuffer(gl.ARRAY_BUFFER, buffer);
    gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
    gl.enableVertexAttribArray(location);
    const type = data instanceof Uint8Array ? gl.UNSIGNED_BYTE : data instanceof Uint16Array ? gl.UNSIGNED_SHORT : gl.FLOAT;
    if (integer) gl.vertexAttribIPointer(location, size, type, 0, 0);
    else gl.vertexAttribPointer(location, size, type, false, 0, 0);
  };
  attribute("aPosition", arrays.position, 3);
  attribute("aNormal", arrays.normal, 3);
  attribute("aUv", arrays.uv, 2);
  attribute("aJoints", arrays.joints, 4, true);
  attribute("aWeights", arrays.weights, 4);
  const indices = gl.createBuffer();
  buffers.push(indices);
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, indices);
  gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, arrays.indices, gl.STATIC_DRAW);
  gl.bindVertexArray(null);

  const textures = images.map((image) => {
    if (!image) return null;
    const t = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, t);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA, gl.RGBA, gl.UNSIGNED_BYTE, image);
    gl.generateMipmap(gl.TEXTURE_2D);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR_MIPMAP_LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.REPEAT);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.REPEAT);
    return t;
  });
  const joints = header.joints.length;
  const skinningTexture = gl.createTexture();
  gl.bindTexture(gl.TEXTURE_2D, skinningTexture);
  gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA32F, 4, joints);
  for (const p of [gl.TEXTURE_MIN_FILTER, gl.TEXTURE_MAG_FILTER]) gl.texParameteri(gl.TEXTURE_2D, p, gl.NEAREST);
  const binds = arrays.inverse_binds;
  gpu = {
    vao,
    buffers,
    textures,
    skinning: skinningTexture,
    indexType: arrays.indices instanceof Uint32Array ? gl.UNSIGNED_INT : gl.UNSIGNED_SHORT,
    indexSize: arrays.indices.BYTES_PER_ELEMENT,
    primitives: header.primitives,
    materials: header.materials,
    joints: header.joints,
    inverseBinds: header.joints.map((_, k) => Array.from(binds.subarray(16 * k, 16 * k + 16))),
    normals: Boolean(arrays.normal),
    posed: false,
  };
  skinning = new Float32Array(16 * joints);
  palette = null;
}

// ---- drawing ----

/// Whether the mesh view is on (a mesh loaded): then it draws the
/// background, the ground lines scene.js gives and the mesh, and the 2D
/// canvas above only the skeleton. Called by scene.js's drawScene.
export function draw(cam, width, height, lines) {
  if (!mesh.clip || !gpu || !gl) return false;
  if (canvas.width !== width || canvas.height !== height) {
    canvas.width = width;
    canvas.height = height;
  }
  gl.viewport(0, 0, width, height);
  gl.clearColor(...BACKGROUND, 1);
  gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
  const vp = viewProjection(cam, state.camera, width, height);
  drawLines(vp, lines);
  if (mesh.showMesh && gpu.posed) drawMesh(vp, cam);
  depth = mesh.showMesh && gpu.posed && mesh.showSkeleton ? readDepth(vp, width, height) : null;
  return true;
}

// ---- the mesh's depth, for the skeleton drawn over it (scene.js dims the bones behind it) ----

/// The depth map is read at this fraction of the view's size: enough to tell a leg from the body behind it.
const DEPTH_SCALE = 4;
let depth = null; // { width, height, data, near, far } of the last frame drawn with the mesh
let depthTarget = null; // { fbo, color, depth, width, height }

/// Renders the posed mesh's depth at a quarter of the view's size and reads it back.
function readDepth(vp, width, height) {
  const w = Math.max(1, Math.round(width / DEPTH_SCALE)), h = Math.max(1, Math.round(height / DEPTH_SCALE));
  if (!depthTarget || depthTarget.width !== w || depthTarget.height !== h) makeDepthTarget(w, h);
  gl.bindFramebuffer(gl.FRAMEBUFFER, depthTarget.fbo);
  gl.viewport(0, 0, w, h);
  gl.clearColor(1, 1, 1, 1);
  gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
  gl.enable(gl.DEPTH_TEST);
  const d = programs.depth;
  gl.useProgram(d.program);
  gl.uniformMatrix4fv(d.uniforms.uViewProjection, false, vp);
  gl.activeTexture(gl.TEXTURE0);
  gl.bindTexture(gl.TEXTURE_2D, gpu.skinning);
  gl.uniform1i(d.uniforms.uSkinning, 0);
  gl.bindVertexArray(gpu.vao);
  for (const p of gpu.primitives) gl.drawElements(gl.TRIANGLES, p.count, gpu.indexType, p.first * gpu.indexSize);
  gl.bindVertexArray(null);
  const data = new Uint8Array(4 * w * h);
  gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, data);
  gl.bindFramebuffer(gl.FRAMEBUFFER, null);
  gl.viewport(0, 0, width, height);
  // viewProjection's depth range, to turn a stored depth back into a distance along the view.
  const near = Math.max(state.camera.dist * 1e-3, state.camera.dist * 0.01), far = state.camera.dist + 40 * state.camera.radius;
  return { width: w, height: h, data, near, far };
}

function makeDepthTarget(w, h) {
  if (depthTarget) {
    gl.deleteFramebuffer(depthTarget.fbo);
    gl.deleteTexture(depthTarget.color);
    gl.deleteRenderbuffer(depthTarget.depth);
  }
  const color = gl.createTexture();
  gl.bindTexture(gl.TEXTURE_2D, color);
  gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA8, w, h);
  const depthBuffer = gl.createRenderbuffer();
  gl.bindRenderbuffer(gl.RENDERBUFFER, depthBuffer);
  gl.renderbufferStorage(gl.RENDERBUFFER, gl.DEPTH_COMPONENT24, w, h);
  const fbo = gl.createFramebuffer();
  gl.bindFramebuffer(gl.FRAMEBUFFER, fbo);
  gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, color, 0);
  gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.DEPTH_ATTACHMENT, gl.RENDERBUFFER, depthBuffer);
  gl.bindFramebuffer(gl.FRAMEBUFFER, null);
  depthTarget = { fbo, color, depth: depthBuffer, width: w, height: h };
}

/// The distance along the view to the mesh's nearest surface around
/// screen point `[x, y]` (the view's pixels, y down), or Infinity where no
/// mesh is drawn; null when the last frame had no mesh depth.
export function meshDistanceAt([x, y]) {
  if (!depth) return null;
  const { width: w, height: h, data, near, far } = depth;
  const cx = Math.round(x / DEPTH_SCALE), cy = h - 1 - Math.round(y / DEPTH_SCALE);
  let nearest = Infinity;
  for (let j = cy - 1; j <= cy + 1; j++)
    for (let i = cx - 1; i <= cx + 1; i++) {
      if (i < 0 || j < 0 || i >= w || j >= h) continue;
      const k = 4 * (j * w + i);
      const z = data[k] / 255 + data[k + 1] / 65025 + data[k + 2] / 16581375 + data[k + 3] / 4228250625;
      if (z >= 0.999999) continue; // cleared: no mesh here
      const ndc = 2 * z - 1; // back through viewProjection's depth: ndc = a + b / distance
      const a = (far + near) / (far - near), b = (-2 * far * near) / (far - near);
      nearest = Math.min(nearest, b / (ndc - a));
    }
  return nearest;
}

function drawLines(vp, lines) {
  const l = programs.line;
  gl.useProgram(l.program);
  gl.uniformMatrix4fv(l.uniforms.uViewProjection, false, vp);
  gl.disable(gl.DEPTH_TEST);
  gl.bindVertexArray(null);
  gl.bindBuffer(gl.ARRAY_BUFFER, programs.lineBuffer);
  const at = l.attribute("aPosition");
  gl.enableVertexAttribArray(at);
  for (const { color, segments } of lines) {
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(segments.flat(2)), gl.STREAM_DRAW);
    gl.vertexAttribPointer(at, 3, gl.FLOAT, false, 0, 0);
    gl.uniform4fv(l.uniforms.uColor, color);
    gl.drawArrays(gl.LINES, 0, segments.length * 2);
  }
  gl.disableVertexAttribArray(at);
}

function drawMesh(vp, cam) {
  const s = programs.skin;
  gl.enable(gl.DEPTH_TEST);
  gl.useProgram(s.program);
  gl.uniformMatrix4fv(s.uniforms.uViewProjection, false, vp);
  gl.activeTexture(gl.TEXTURE0);
  gl.bindTexture(gl.TEXTURE_2D, gpu.skinning);
  gl.texSubImage2D(gl.TEXTURE_2D, 0, 0, 0, 4, gpu.joints.length, gl.RGBA, gl.FLOAT, skinning);
  gl.uniform1i(s.uniforms.uSkinning, 0);
  gl.uniform1i(s.uniforms.uTexture, 1);
  gl.uniform1i(s.uniforms.uNormals, gpu.normals ? 1 : 0);
  const light = [0.6 * cam.u[0] - 0.4 * cam.r[0] - cam.f[0], 0.6 * cam.u[1] - 0.4 * cam.r[1] - cam.f[1], 0.6 * cam.u[2] - 0.4 * cam.r[2] - cam.f[2]];
  const n = Math.hypot(...light) || 1;
  gl.uniform3f(s.uniforms.uLight, light[0] / n, light[1] / n, light[2] / n);
  gl.uniform3f(s.uniforms.uEye, ...cam.eye);
  gl.bindVertexArray(gpu.vao);
  for (const p of gpu.primitives) {
    const material = gpu.materials[p.material];
    const texture = material.texture != null ? gpu.textures[material.texture] : null;
    gl.activeTexture(gl.TEXTURE1);
    gl.bindTexture(gl.TEXTURE_2D, texture);
    gl.uniform1i(s.uniforms.uTextured, texture ? 1 : 0);
    gl.uniform4fv(s.uniforms.uBaseColor, material.base_color);
    gl.drawElements(gl.TRIANGLES, p.count, gpu.indexType, p.first * gpu.indexSize);
  }
  gl.bindVertexArray(null);
  mesh.draws += 1;
}
