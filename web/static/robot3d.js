// 3D view of the robot from its URDF (three.js + urdf-loader, served from web/node_modules).
// Loaded lazily: if WebGL or the modules are missing, the rest of the dashboard still works.

export async function createRobotView(container, urdfUrl) {
  const fail = (why) => {
    container.innerHTML = `<div class="fallback">3D view unavailable: ${why}</div>`;
    container.dataset.loaded = "error";
    return null;
  };
  let THREE, URDFLoader, OrbitControls;
  try {
    THREE = await import("three");
    ({ default: URDFLoader } = await import("urdf-loader"));
    ({ OrbitControls } = await import("three/examples/jsm/controls/OrbitControls.js"));
  } catch (err) {
    return fail("three.js / urdf-loader not installed (run make install)");
  }
  let renderer;
  try {
    renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  } catch (err) {
    return fail("this browser has no WebGL");
  }
  const w = container.clientWidth, h = container.clientHeight;
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.setSize(w, h);
  container.appendChild(renderer.domElement);

  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0x0b0e12);
  const camera = new THREE.PerspectiveCamera(45, w / h, 0.01, 20);
  camera.position.set(1.55, 1.05, 1.45); // the arm, the table and the camera on its mount in view
  scene.add(new THREE.HemisphereLight(0xffffff, 0x334455, 1.6));
  const sun = new THREE.DirectionalLight(0xffffff, 1.8);
  sun.position.set(2, 4, 3);
  scene.add(sun);
  const grid = new THREE.GridHelper(1.6, 16, 0x3a4656, 0x232b36);
  scene.add(grid);
  // URDF is z-up; three.js is y-up
  const world = new THREE.Group();
  world.rotation.x = -Math.PI / 2;
  scene.add(world);

  const controls = new OrbitControls(camera, renderer.domElement);
  controls.target.set(0.35, 0.2, 0.0);
  controls.update();

  let text;
  try {
    const res = await fetch(urdfUrl);
    if (!res.ok) return fail(`no URDF (${res.status})`);
    text = await res.text();
  } catch (err) {
    return fail("URDF not reachable");
  }
  const loader = new URDFLoader();
  loader.parseCollision = true; // the project's URDFs carry primitive collision geometry only
  const robot = loader.parse(text);
  const palette = [0xc9d1d9, 0x4493f8, 0xc9d1d9, 0x4493f8, 0xc9d1d9, 0x4493f8, 0xd29922, 0x8b96a5];
  let i = 0;
  robot.traverse((o) => {
    if (o.isMesh) {
      o.material = new THREE.MeshStandardMaterial({ color: palette[i++ % palette.length], roughness: 0.6, metalness: 0.2 });
    }
  });
  world.add(robot);

  let dirty = true;
  controls.addEventListener("change", () => { dirty = true; });
  const render = () => {
    if (dirty) { renderer.render(scene, camera); dirty = false; }
    requestAnimationFrame(render);
  };
  requestAnimationFrame(render);
  new ResizeObserver(() => { // the panel follows the window (1280–1920 px and beyond)
    const cw = container.clientWidth, ch = container.clientHeight;
    if (!cw || !ch) return;
    renderer.setSize(cw, ch);
    camera.aspect = cw / ch;
    camera.updateProjectionMatrix();
    dirty = true;
  }).observe(container);
  container.dataset.loaded = "true";

  // what vision sees (base frame, as the detection list): the table, rods, cubes, obstacle boxes;
  // and where the task puts things (the place targets from the settings)
  const table = new THREE.Mesh(new THREE.PlaneGeometry(0.9, 1.3),
    new THREE.MeshStandardMaterial({ color: 0x5a5048, roughness: 0.9, transparent: true, opacity: 0.85 }));
  table.position.set(0.5, 0.0, -0.001);
  world.add(table);
  const objects = new THREE.Group(), targets = new THREE.Group();
  const frustum = new THREE.Group(), plans = new THREE.Group();
  world.add(objects, targets, frustum, plans);
  const COLOR = { red: 0xe5534b, green: 0x3fb950, blue: 0x4493f8, yellow: 0xe3b341, black: 0x222222 };
  const clear = (g) => { while (g.children.length) { const c = g.children.pop(); c.geometry?.dispose(); } };
  const up = new THREE.Vector3(0, 1, 0);
  let shown = 0;

  return {
    setJoints(names, positions) {
      names.forEach((n, k) => { if (robot.joints[n]) robot.joints[n].setJointValue(positions[k]); });
      dirty = true;
    },
    setDetections(d) {
      clear(objects);
      for (const o of d.objects) {
        if (!o.base) continue;
        let mesh;
        if (o.kind === "rod") {
          mesh = new THREE.Mesh(new THREE.CylinderGeometry((o.diameter_m || 0.02) / 2, (o.diameter_m || 0.02) / 2, o.length_m || 0.2, 16),
            new THREE.MeshStandardMaterial({ color: 0x30363d, metalness: 0.8, roughness: 0.3 }));
          mesh.position.set(...o.base);
          if (o.axis && Math.hypot(...o.axis) > 0.5) mesh.quaternion.setFromUnitVectors(up, new THREE.Vector3(...o.axis).normalize());
        } else if (o.kind === "cube") {
          mesh = new THREE.Mesh(new THREE.BoxGeometry(0.05, 0.05, 0.05),
            new THREE.MeshStandardMaterial({ color: COLOR[o.color] ?? 0x8b96a5 }));
          mesh.position.set(...o.base);
        } else {
          const [lo, hi] = o.base;
          const size = hi.map((h, i) => Math.max(h - lo[i], 0.005));
          mesh = new THREE.Mesh(new THREE.BoxGeometry(...size),
            new THREE.MeshStandardMaterial({ color: COLOR[o.color] ?? 0xdb61a2, transparent: true, opacity: 0.35 }));
          mesh.position.set(...lo.map((l, i) => l + size[i] / 2));
        }
        objects.add(mesh);
      }
      shown = objects.children.length;
      container.dataset.objects = String(shown);
      dirty = true;
    },
    // the camera: its body at the calibrated pose and the four corner rays of its image down to the
    // table plane (z = 0; at most 2 m out), the footprint it sees on the table outlined
    setCamera(info) {
      clear(frustum);
      const T = info.T_base_camera;
      if (!T) { container.dataset.frustum = "no pose"; dirty = true; return; }
      const rot = (d) => new THREE.Vector3(
        T[0][0] * d[0] + T[0][1] * d[1] + T[0][2] * d[2],
        T[1][0] * d[0] + T[1][1] * d[1] + T[1][2] * d[2],
        T[2][0] * d[0] + T[2][1] * d[1] + T[2][2] * d[2]);
      const eye = new THREE.Vector3(T[0][3], T[1][3], T[2][3]);
      const corners = [[0, 0], [info.width, 0], [info.width, info.height], [0, info.height]].map(([u, v]) => {
        const ray = rot([(u - info.cx) / info.fx, (v - info.cy) / info.fy, 1]).normalize();
        const reach = ray.z < -1e-6 ? Math.min(-eye.z / ray.z, 2.0) : 2.0;
        return eye.clone().addScaledVector(ray, reach);
      });
      const pts = [];
      corners.forEach((c, k) => pts.push(eye, c, c, corners[(k + 1) % 4]));
      frustum.add(new THREE.LineSegments(new THREE.BufferGeometry().setFromPoints(pts),
        new THREE.LineBasicMaterial({ color: 0x58a6ff })));
      const footprint = new THREE.Mesh(new THREE.BufferGeometry().setFromPoints([corners[0], corners[1], corners[2], corners[0], corners[2], corners[3]]),
        new THREE.MeshBasicMaterial({ color: 0x58a6ff, transparent: true, opacity: 0.08, side: THREE.DoubleSide }));
      frustum.add(footprint);
      const body = new THREE.Mesh(new THREE.BoxGeometry(0.09, 0.025, 0.03),
        new THREE.MeshStandardMaterial({ color: 0x58a6ff, roughness: 0.5 }));
      body.position.copy(eye);
      body.quaternion.setFromRotationMatrix(new THREE.Matrix4().set(
        T[0][0], T[0][1], T[0][2], 0, T[1][0], T[1][1], T[1][2], 0, T[2][0], T[2][1], T[2][2], 0, 0, 0, 0, 1));
      frustum.add(body);
      container.dataset.frustum = "true";
      dirty = true;
    },
    // the current cycle's planned path: the tool tip through each plan the task got, one line per plan
    // (the first in the path colour, later ones lighter), a dot where each plan ends
    setPlan(plan) {
      clear(plans);
      let points = 0;
      (plan.plans || []).forEach((p, k) => {
        if (!p.path || p.path.length < 2) return;
        const v = p.path.map((q) => new THREE.Vector3(...q));
        const color = k === plan.plans.length - 1 ? 0xf0883e : 0xd2a8ff;
        // a thin tube, not a line: WebGL draws lines 1 px wide whatever their width
        const curve = new THREE.CatmullRomCurve3(v, false, "centripetal");
        plans.add(new THREE.Mesh(new THREE.TubeGeometry(curve, Math.min(4 * v.length, 400), 0.003, 6, false),
          new THREE.MeshBasicMaterial({ color })));
        const end = new THREE.Mesh(new THREE.SphereGeometry(0.008, 12, 8), new THREE.MeshBasicMaterial({ color }));
        end.position.copy(v[v.length - 1]);
        plans.add(end);
        points += v.length;
      });
      container.dataset.planPoints = String(points);
      container.dataset.planCycle = String(plan.cycle_index ?? "");
      container.dataset.planSource = plan.source || "";
      dirty = true;
    },
    setTargets(points) { // [[x, y, colour]] on the table
      clear(targets);
      for (const [x, y, c] of points) {
        const ring = new THREE.Mesh(new THREE.RingGeometry(0.025, 0.035, 32),
          new THREE.MeshBasicMaterial({ color: COLOR[c] ?? 0xffffff, side: THREE.DoubleSide }));
        ring.position.set(x, y, 0.002);
        targets.add(ring);
      }
      container.dataset.targets = String(targets.children.length);
      dirty = true;
    },
  };
}
