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

  return {
    setJoints(names, positions) {
      names.forEach((n, k) => { if (robot.joints[n]) robot.joints[n].setJointValue(positions[k]); });
      dirty = true;
    },
  };
}
