// The report's 3D view of posterior samples (sppl/report_view.py writes its data into the page).
// A classic script on purpose: the page opens from file://, where browsers refuse ES modules.
// World axes are sppl's: metres, z up, the ground is z = 0. Each part is a unit shape (the
// same unit shapes as sppl/geometry.py) posed by the 4x4 matrix sppl's renderer draws it with.
(function () {
  "use strict";
  const data = JSON.parse(document.getElementById("sppl-view-data").textContent);
  const $ = (id) => document.getElementById(id);
  const canvas = $("sppl-view-canvas");
  const BACKGROUND = 0xf4f4f4;

  if (typeof THREE === "undefined") {  // three.min.js was not beside the page
    canvas.hidden = true;
    $("sppl-view-nowebgl").textContent = "three.min.js, which draws this view, did not load: " +
      "keep it in the folder of this page.";
    $("sppl-view-nowebgl").hidden = false;
    throw new Error("three.min.js did not load: keep it in the folder of the report's page");
  }

  let renderer;
  try {
    renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
  } catch (error) {
    // No WebGL (an old machine, or a browser with it switched off): say so instead.
    canvas.hidden = true;
    $("sppl-view-nowebgl").hidden = false;
    window.spplViewError = String(error);
    return;
  }
  renderer.setPixelRatio(window.devicePixelRatio || 1);

  const scene = new THREE.Scene();
  scene.background = new THREE.Color(BACKGROUND);
  const hemisphere = new THREE.HemisphereLight(0xffffff, 0x777777, 0.65);
  hemisphere.position.set(0, 0, 1);
  const sun = new THREE.DirectionalLight(0xffffff, 0.6);
  sun.position.set(0.4, -0.3, 1.0);
  scene.add(hemisphere, sun);

  // ---- unit shapes, as in sppl/geometry.py: each rests on the ground, its axis along z.
  const unitShapes = {};
  function unitShape(primitive) {
    if (unitShapes[primitive]) return unitShapes[primitive];
    let g;
    if (primitive === "cylinder") {
      g = new THREE.CylinderGeometry(1, 1, 1, 48).rotateX(Math.PI / 2).translate(0, 0, 0.5);
    } else if (primitive === "cone") {  // three's cone points along +y: turn it to +z
      g = new THREE.ConeGeometry(1, 1, 48).rotateX(Math.PI / 2).translate(0, 0, 0.5);
    } else if (primitive === "sphere") {
      g = new THREE.SphereGeometry(1, 32, 16).translate(0, 0, 1);
    } else if (data.meshes[primitive]) {
      const m = data.meshes[primitive];
      g = new THREE.BufferGeometry();
      g.setAttribute("position", new THREE.Float32BufferAttribute(m.v, 3));
      g.setIndex(m.f);
      g.computeVertexNormals();
    } else {  // "box", and any primitive the view does not know, as its box
      g = new THREE.BoxGeometry(1, 1, 1).translate(0, 0, 0.5);
    }
    unitShapes[primitive] = g;
    return g;
  }

  // The truth is drawn as edges: a box's twelve, the rims of cylinders and cones, three great
  // circles of a sphere (a smooth sphere has no edges to find).
  const unitEdges = {};
  function unitEdge(primitive) {
    if (unitEdges[primitive]) return unitEdges[primitive];
    let g;
    if (primitive === "sphere") {
      const points = [];
      const n = 48;
      for (let k = 0; k < n; k++) {
        const a = (2 * Math.PI * k) / n, b = (2 * Math.PI * (k + 1)) / n;
        const rings = [
          [Math.cos(a), Math.sin(a), 1, Math.cos(b), Math.sin(b), 1],
          [Math.cos(a), 0, 1 + Math.sin(a), Math.cos(b), 0, 1 + Math.sin(b)],
          [0, Math.cos(a), 1 + Math.sin(a), 0, Math.cos(b), 1 + Math.sin(b)],
        ];
        for (const r of rings) points.push(...r);
      }
      g = new THREE.BufferGeometry();
      g.setAttribute("position", new THREE.Float32BufferAttribute(points, 3));
    } else {
      g = new THREE.EdgesGeometry(unitShape(primitive), 30);
    }
    unitEdges[primitive] = g;
    return g;
  }

  const materials = {};
  function material(colour, kind) {
    const key = kind + colour.join(",");
    if (!materials[key]) {
      const color = new THREE.Color(colour[0], colour[1], colour[2]);
      materials[key] = kind === "ghost"
        ? new THREE.MeshLambertMaterial({ color, transparent: true, opacity: data.ghost_opacity,
          depthWrite: false })
        : new THREE.MeshLambertMaterial({ color });
    }
    return materials[key];
  }
  const truthMaterial = new THREE.LineBasicMaterial({ color: 0x000000 });

  function posed(object3d, matrix) {
    object3d.matrixAutoUpdate = false;
    object3d.matrix.fromArray(matrix);
    return object3d;
  }

  function partsGroup(parts, kind) {
    const group = new THREE.Group();
    for (const part of parts) {
      group.add(posed(kind === "truth"
        ? new THREE.LineSegments(unitEdge(part.p), truthMaterial)
        : new THREE.Mesh(unitShape(part.p), material(part.c, kind)), part.m));
    }
    return group;
  }

  function sceneGroup(index, kind) {
    const parts = [];
    for (const object of data.scenes[index]) parts.push(...object.parts);
    return partsGroup(parts, kind);
  }

  // ---- the ground, the scenery, the cameras
  const [x0, x1, y0, y1] = data.extent;
  const span = Math.max(x1 - x0, y1 - y0);
  const centre = new THREE.Vector3((x0 + x1) / 2, (y0 + y1) / 2, 0);
  const size = Math.ceil(1.5 * span);  // metres of ground drawn, in 1 m squares
  const ground = new THREE.Mesh(new THREE.PlaneGeometry(size, size),
    new THREE.MeshLambertMaterial({ color: 0xaaaaaa }));
  ground.position.set(centre.x, centre.y, -0.002);
  const grid = new THREE.GridHelper(size, size, 0x777777, 0x888888);
  grid.rotateX(Math.PI / 2);  // three's grid lies in x-z; sppl's ground is x-y
  grid.position.set(centre.x, centre.y, 0.002);  // above a model's own ground, if it has one
  scene.add(ground, grid, partsGroup(data.static, "solid"));

  function label(text, colour) {
    const c = document.createElement("canvas");
    c.width = 256;
    c.height = 64;
    const g = c.getContext("2d");
    g.font = "bold 36px sans-serif";
    g.fillStyle = colour;
    g.textBaseline = "middle";
    g.fillText(text, 4, 32);
    const sprite = new THREE.Sprite(new THREE.SpriteMaterial({
      map: new THREE.CanvasTexture(c), depthTest: false, transparent: true }));
    sprite.scale.set(0.08 * span, 0.02 * span, 1);
    sprite.center.set(0, 0);
    return sprite;
  }

  const cameraGroup = new THREE.Group();
  for (const cam of data.cameras) {
    const c2w = new THREE.Matrix4().fromArray(cam.c2w);
    const position = new THREE.Vector3().setFromMatrixPosition(c2w);
    const d = Math.min(1.0, 0.3 * position.distanceTo(centre));  // frustum depth drawn (m)
    // The image's corners at depth d, in OpenGL camera axes (looking along -z, +y up).
    const corners = [[0, 0], [cam.w, 0], [cam.w, cam.h], [0, cam.h]].map(([u, v]) =>
      [((u - cam.cx) / cam.fx) * d, (-(v - cam.cy) / cam.fy) * d, -d]);
    const points = [];
    corners.forEach((p, k) => {
      points.push(0, 0, 0, ...p, ...p, ...corners[(k + 1) % 4]);
    });
    const lines = new THREE.BufferGeometry();
    lines.setAttribute("position", new THREE.Float32BufferAttribute(points, 3));
    cameraGroup.add(posed(new THREE.LineSegments(lines,
      new THREE.LineBasicMaterial({ color: 0x2ca02c })), cam.c2w));
    const tag = label(cam.name, "#2ca02c");
    tag.position.copy(position);
    cameraGroup.add(tag);
  }
  scene.add(cameraGroup);

  // ---- what the samples say
  const ghosts = new THREE.Group();
  for (const index of data.ghosts) ghosts.add(sceneGroup(index, "ghost"));
  const truth = data.truth === null ? new THREE.Group() : sceneGroup(data.truth, "truth");
  let solid = sceneGroup(data.map, "solid");
  scene.add(ghosts, truth, solid);
  if (data.truth === null) $("sppl-truth-label").hidden = true;

  // ---- the viewer's camera and a small orbit control (drag: turn; shift- or right-drag:
  // move; wheel: zoom; double-click: back to the start)
  const view = new THREE.PerspectiveCamera(45, 1, 0.01, 200);
  view.up.set(0, 0, 1);
  const orbit = { target: new THREE.Vector3(), r: 1, az: 0, el: 0 };

  function home() {
    orbit.target.set(centre.x, centre.y, 0.2);
    orbit.r = 1.0 * span;
    orbit.az = -Math.PI / 2 - 0.5;  // from the -y side, a little to the left
    orbit.el = 0.6;
    view.fov = 45;
    view.updateProjectionMatrix();
    place();
  }

  function place() {
    const ce = Math.cos(orbit.el);
    view.position.set(orbit.target.x + orbit.r * ce * Math.cos(orbit.az),
      orbit.target.y + orbit.r * ce * Math.sin(orbit.az),
      orbit.target.z + orbit.r * Math.sin(orbit.el));
    view.lookAt(orbit.target);
    draw();
  }

  // Look through one of sppl's cameras: put the viewer where it is, looking where it looks,
  // with its vertical field of view (the window's shape crops the sides differently).
  function lookThrough(cam) {
    const c2w = new THREE.Matrix4().fromArray(cam.c2w);
    const position = new THREE.Vector3().setFromMatrixPosition(c2w);
    const forward = new THREE.Vector3().setFromMatrixColumn(c2w, 2).negate().normalize();
    const dist = Math.max(0.5, centre.clone().sub(position).dot(forward));
    orbit.target.copy(position).addScaledVector(forward, dist);
    orbit.r = dist;
    orbit.el = Math.asin(Math.max(-1, Math.min(1, -forward.z)));
    orbit.az = Math.atan2(-forward.y, -forward.x);
    view.fov = (2 * Math.atan(cam.h / 2 / cam.fy) * 180) / Math.PI;
    view.updateProjectionMatrix();
    place();
  }

  let drag = null;
  canvas.addEventListener("pointerdown", (e) => {
    drag = { x: e.clientX, y: e.clientY, pan: e.button === 2 || e.shiftKey };
    canvas.setPointerCapture(e.pointerId);
  });
  canvas.addEventListener("pointermove", (e) => {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    drag.x = e.clientX;
    drag.y = e.clientY;
    if (drag.pan) {
      const k = (orbit.r * 1.5) / canvas.clientHeight;
      const right = new THREE.Vector3().setFromMatrixColumn(view.matrixWorld, 0);
      const up = new THREE.Vector3().setFromMatrixColumn(view.matrixWorld, 1);
      orbit.target.addScaledVector(right, -dx * k).addScaledVector(up, dy * k);
    } else {
      orbit.az -= dx * 0.008;
      orbit.el = Math.max(-0.3, Math.min(1.55, orbit.el + dy * 0.008));
    }
    place();
  });
  canvas.addEventListener("pointerup", () => { drag = null; });
  canvas.addEventListener("contextmenu", (e) => e.preventDefault());
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    orbit.r = Math.max(0.05 * span, Math.min(10 * span, orbit.r * Math.exp(e.deltaY * 0.001)));
    place();
  }, { passive: false });
  canvas.addEventListener("dblclick", home);
  $("sppl-view-reset").addEventListener("click", home);
  for (const cam of data.cameras) {
    const b = document.createElement("button");
    b.type = "button";
    b.textContent = "look through " + cam.name;
    b.addEventListener("click", () => lookThrough(cam));
    $("sppl-view-from").appendChild(b);
  }

  // ---- layers
  const layers = { map: () => solid, ghosts: () => ghosts, truth: () => truth,
    cameras: () => cameraGroup };
  function show(options) {
    for (const [name, on] of Object.entries(options)) {
      $("sppl-show-" + name).checked = on;
      layers[name]().visible = on;
    }
    draw();
  }
  for (const name of Object.keys(layers)) {
    $("sppl-show-" + name).addEventListener("change",
      (e) => show({ [name]: e.target.checked }));
  }

  // ---- the chain's best scene so far, under a slider
  const chainSelect = $("sppl-chain"), slider = $("sppl-frame"), play = $("sppl-play");
  data.chains.forEach((c, k) => {
    const option = document.createElement("option");
    option.value = k;
    option.textContent = String(c.chain) + (c.chain === data.map_chain ? " (the MAP's)" : "");
    chainSelect.appendChild(option);
  });
  if (data.chains.length < 2) $("sppl-chain-label").hidden = true;
  let chain = Math.max(0, data.chains.findIndex((c) => c.chain === data.map_chain));

  function setFrame(k) {
    const frames = data.chains.length ? data.chains[chain].frames : [];
    if (!frames.length) return;
    k = Math.max(0, Math.min(frames.length - 1, k));
    slider.value = k;
    const f = frames[k];
    const last = k === frames.length - 1;
    const visible = solid.visible;
    scene.remove(solid);
    solid = sceneGroup(f.scene, "solid");
    solid.visible = visible;
    scene.add(solid);
    const what = last && data.chains[chain].chain === data.map_chain && f.scene === data.map
      ? "the MAP scene" : last ? "this chain's best scene" : "the best scene so far";
    $("sppl-frame-label").textContent = "improvement " + (k + 1) + " of " + frames.length +
      ", sweep " + f.step + ": " + what + ", " + f.n + " object" + (f.n === 1 ? "" : "s") +
      ", log joint " + f.score.toFixed(1);
    draw();
  }
  function setChain(k) {
    chain = k;
    chainSelect.value = k;
    const n = data.chains.length ? data.chains[k].frames.length : 0;
    slider.max = Math.max(0, n - 1);
    setFrame(n - 1);
  }
  chainSelect.addEventListener("change", () => setChain(Number(chainSelect.value)));
  slider.addEventListener("input", () => setFrame(Number(slider.value)));
  let timer = null;
  function stop() {
    clearInterval(timer);
    timer = null;
    play.innerHTML = "&#9654; replay";
  }
  play.addEventListener("click", () => {
    if (timer !== null) { stop(); return; }
    setFrame(0);
    play.innerHTML = "&#10073;&#10073; pause";
    timer = setInterval(() => {
      if (Number(slider.value) >= Number(slider.max)) { stop(); return; }
      setFrame(Number(slider.value) + 1);
    }, 150);
  });

  // ---- drawing, on demand (nothing moves unless the reader moves it)
  let pending = false;
  function draw() {
    if (pending) return;
    pending = true;
    requestAnimationFrame(() => { pending = false; renderNow(); });
  }
  function renderNow() {
    renderer.render(scene, view);
  }
  function resize() {
    const w = canvas.clientWidth, h = canvas.clientHeight;
    renderer.setSize(w, h, false);
    view.aspect = w / Math.max(h, 1);
    view.updateProjectionMatrix();
    draw();
  }
  window.addEventListener("resize", resize);

  // A hook for tests (and the curious, from the browser's console).
  window.spplView = {
    show,
    setChain,
    setFrame,
    lookThrough: (k) => lookThrough(data.cameras[k]),
    counts: () => ({
      solid: solid.children.length, ghosts: ghosts.children.length,
      truth: truth.children.length, cameras: data.cameras.length,
      chains: data.chains.length,
      frames: data.chains.length ? data.chains[chain].frames.length : 0,
    }),
    // Where world points fall on the canvas, in CSS pixels from its top-left corner.
    project: (points) => {
      renderNow();
      return points.map(([x, y, z]) => {
        const p = new THREE.Vector3(x, y, z).project(view);
        return [((p.x + 1) / 2) * canvas.clientWidth, ((1 - p.y) / 2) * canvas.clientHeight];
      });
    },
    // Pixels of the drawn frame whose colour is far from grey (the ground, grid and
    // background are grey; objects, ghosts and frusta are coloured).
    colouredPixels: () => {
      renderNow();
      const gl = renderer.getContext();
      const w = gl.drawingBufferWidth, h = gl.drawingBufferHeight;
      const px = new Uint8Array(w * h * 4);
      gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, px);
      let n = 0;
      for (let i = 0; i < px.length; i += 4) {
        const hi = Math.max(px[i], px[i + 1], px[i + 2]), lo = Math.min(px[i], px[i + 1], px[i + 2]);
        if (hi - lo > 60) n++;
      }
      return n;
    },
  };

  resize();
  home();
  setChain(chain);
  renderNow();
  window.spplViewReady = true;
})();
