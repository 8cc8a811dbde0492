// The simulated final state in 3D: the run's .glb (undulate export) in three.js, orbit/zoom.
// Loaded as a module; app.js calls window.undulate3d.show(url) and falls back to a message
// where the browser has no WebGL. Coordinates: mm, z up (the fabric's normal), x the stretch.
import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
import { GLTFLoader } from "three/addons/loaders/GLTFLoader.js";

const BACKGROUND = 0xfbfbfb;
let renderer = null;
let scene = null;
let camera = null;
let controls = null;

function render() { if (renderer) renderer.render(scene, camera); }

function setUp(canvas) {
  try {
    // preserveDrawingBuffer: the picture stays readable (tests, right-click "save image")
    renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
  } catch (e) {
    return false;
  }
  renderer.setPixelRatio(1);
  renderer.setClearColor(BACKGROUND, 1);
  camera = new THREE.PerspectiveCamera(35, canvas.width / canvas.height, 0.1, 1e5);
  camera.up.set(0, 0, 1);
  controls = new OrbitControls(camera, canvas);
  controls.addEventListener("change", render);
  canvas.addEventListener("dblclick", () => { controls.reset(); render(); });
  return true;
}

function clearScene() {
  scene = new THREE.Scene();
  scene.add(new THREE.HemisphereLight(0xffffff, 0x8899aa, 1.6));
  const sun = new THREE.DirectionalLight(0xffffff, 1.8);
  sun.position.set(-0.6, 0.3, 0.75);
  scene.add(sun);
}

// Show the model at url; true when drawn, false where WebGL or the file is not available.
async function show(url, canvas) {
  if (!renderer && !setUp(canvas)) return false;
  let gltf;
  try {
    gltf = await new GLTFLoader().loadAsync(url);
  } catch (e) {
    return false;
  }
  clearScene();
  scene.add(gltf.scene);
  // frame the rods (the fabric sheet around them is much larger)
  const box = new THREE.Box3();
  gltf.scene.traverse((o) => { if (o.isMesh && o.name.startsWith("rod_")) box.expandByObject(o); });
  if (box.isEmpty()) box.setFromObject(gltf.scene);
  const centre = box.getCenter(new THREE.Vector3());
  const size = box.getSize(new THREE.Vector3());
  const r = 0.6 * Math.max(size.x, size.y, 4 * size.z, 10);
  camera.near = r / 100;
  camera.far = r * 100;
  camera.position.set(centre.x - 0.9 * r, centre.y - 1.8 * r, centre.z + 1.1 * r);
  camera.updateProjectionMatrix();
  controls.target.copy(centre);
  controls.update();
  controls.saveState();  // what a double-click goes back to
  render();
  return true;
}

window.undulate3d = { show };
window.dispatchEvent(new Event("undulate3d-ready"));
