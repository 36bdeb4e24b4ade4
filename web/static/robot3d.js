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
  camera.position.set(1.25, 0.75, 1.0);
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
  controls.target.set(0.1, 0.3, 0.0);
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
  container.dataset.loaded = "true";

  // what vision sees (base frame, as the detection list): the table, rods, cubes, obstacle boxes;
  // and where the task puts things (the place targets from the settings)
  const table = new THREE.Mesh(new THREE.PlaneGeometry(0.9, 1.3),
    new THREE.MeshStandardMaterial({ color: 0x5a5048, roughness: 0.9, transparent: true, opacity: 0.85 }));
  table.position.set(0.5, 0.0, -0.001);
  world.add(table);
  const objects = new THREE.Group(), targets = new THREE.Group();
  world.add(objects, targets);
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
