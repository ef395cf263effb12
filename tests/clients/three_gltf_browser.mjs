// Play a skinned .glb with three.js's GLTFLoader in headless Chromium (WebGL on SwiftShader) and
// take screenshots of the character at chosen animation times and camera angles.
//
// Run by tests/test_gltf.py as
//     node tests/clients/three_gltf_browser.mjs FILE.glb OUT_DIR SHOTS [CHROMIUM]
// SHOTS: comma-separated NAME:TIME:AZIMUTH[:DISTANCE[:HEIGHT]], TIME in seconds or "rest" (the
// bind pose), AZIMUTH in degrees about the vertical (0: the camera looks at the character's front,
// +Z); the camera, DISTANCE metres away (default 4), looks at HEIGHT metres (default 0.9) above
// the floor under the hips.
// A tiny http server on 127.0.0.1 serves the page, three.js and the file. Writes
// OUT_DIR/NAME.png (640x480) for each shot and prints one JSON object on stdout: the model
// three.js loaded, each shot's path and the skinned vertices' bounding box, and any errors.
import { createServer } from 'node:http';
import { readFile } from 'node:fs/promises';
import { extname, join, normalize } from 'node:path';
import { fileURLToPath } from 'node:url';
import { launchChromium } from './headless.mjs';

const [file, outDir, shotsArg, executablePath = '/usr/bin/chromium'] = process.argv.slice(2);
const here = fileURLToPath(new URL('.', import.meta.url));
const threeRoot = join(here, 'node_modules', 'three');
const report = { ok: false, errors: [], console: [], model: null, shots: [] };

const PAGE = `<!doctype html><html><head><meta charset="utf-8"><style>body{margin:0;background:#000}</style>
<script type="importmap">{"imports": {"three": "/three/build/three.module.js",
  "three/addons/": "/three/examples/jsm/"}}</script></head><body><script type="module">
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(1);
renderer.setSize(640, 480);
renderer.shadowMap.enabled = true;
document.body.appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0xdcdcdc);               // neutral greys: the figure is what has colour
const camera = new THREE.PerspectiveCamera(30, 640 / 480, 0.1, 50);
scene.add(new THREE.HemisphereLight(0xffffff, 0x8a8580, 1.6));
const sun = new THREE.DirectionalLight(0xffffff, 2.2);
sun.castShadow = true;
sun.shadow.mapSize.set(1024, 1024);
Object.assign(sun.shadow.camera, { left: -2, right: 2, top: 2, bottom: -2, near: 0.5, far: 12 });
scene.add(sun, sun.target);
const fill = new THREE.DirectionalLight(0xffffff, 0.6);
fill.position.set(-3, 2, -2);
scene.add(fill);
const floor = new THREE.Mesh(new THREE.CircleGeometry(30, 64), new THREE.MeshLambertMaterial({ color: 0xbdbdbd }));
floor.rotation.x = -Math.PI / 2;
floor.receiveShadow = true;
scene.add(floor);
window.state = 'loading';
new GLTFLoader().load('/model.glb', (gltf) => {
  const skinned = [];
  gltf.scene.traverse((o) => { if (o.isSkinnedMesh) { skinned.push(o); o.castShadow = true; } });
  scene.add(gltf.scene);
  const mixer = new THREE.AnimationMixer(gltf.scene);
  const clip = gltf.animations[0];
  const action = clip ? mixer.clipAction(clip) : null;
  if (action) { action.setLoop(THREE.LoopOnce, 1); action.clampWhenFinished = true; action.play(); }
  const hips = skinned.length ? skinned[0].skeleton.bones[0] : gltf.scene;
  window.model = {
    skinnedMeshes: skinned.length,
    bones: skinned.length ? skinned[0].skeleton.bones.map((b) => b.name) : [],
    vertices: skinned.length ? skinned[0].geometry.attributes.position.count : 0,
    triangles: skinned.length ? skinned[0].geometry.index.count / 3 : 0,
    vertexColors: skinned.length ? !!skinned[0].material.vertexColors : false,
    duration: clip ? clip.duration : null,
  };
  window.shoot = (time, azimuth, distance, height) => {
    if (time === 'rest') { mixer.stopAllAction(); skinned.forEach((m) => m.skeleton.pose()); }
    else { if (action) action.play(); mixer.setTime(Number(time)); }
    gltf.scene.updateMatrixWorld(true);
    // three.js culls a skinned mesh by bounds it computes once; the dancer travels, so recompute them.
    skinned.forEach((m) => { m.computeBoundingBox(); m.computeBoundingSphere(); });
    const centre = hips.getWorldPosition(new THREE.Vector3()).setY(height);
    const a = azimuth * Math.PI / 180;
    camera.position.set(centre.x + distance * Math.sin(a), height + 0.1 * distance, centre.z + distance * Math.cos(a));
    camera.lookAt(centre);
    sun.position.set(centre.x + 1.5, 4, centre.z + 3);
    sun.target.position.copy(centre);
    renderer.render(scene, camera);
    const box = new THREE.Box3(), v = new THREE.Vector3();
    for (const m of skinned) {
      for (let i = 0; i < m.geometry.attributes.position.count; i++) {
        m.getVertexPosition(i, v);                             // skinned, in the mesh's space
        box.expandByPoint(v.applyMatrix4(m.matrixWorld));
      }
    }
    return { min: box.min.toArray(), max: box.max.toArray() };
  };
  window.state = 'ready';
}, undefined, (err) => { window.state = 'error'; window.error = String(err); });
</script></body></html>`;

const TYPES = { '.js': 'text/javascript', '.glb': 'model/gltf-binary', '.html': 'text/html' };
const server = createServer(async (req, res) => {
	try {
		const url = decodeURIComponent(new URL(req.url, 'http://x').pathname);
		let body;
		if (url === '/') body = PAGE;
		else if (url === '/favicon.ico') { res.writeHead(204); res.end(); return; }
		else if (url === '/model.glb') body = await readFile(file);
		else if (url.startsWith('/three/')) {
			const path = normalize(join(threeRoot, url.slice('/three/'.length)));
			if (!path.startsWith(threeRoot)) throw new Error('outside three');
			body = await readFile(path);
		} else throw new Error('not found');
		res.writeHead(200, { 'Content-Type': TYPES[extname(url)] || 'text/html' });
		res.end(body);
	} catch (e) {
		res.writeHead(404);
		res.end(String(e));
	}
});
await new Promise((resolve) => server.listen(0, '127.0.0.1', resolve));

let browser;
try {
	browser = await launchChromium(executablePath);
	const page = await browser.newPage({ viewport: { width: 640, height: 480 } });
	page.setDefaultTimeout(30000);
	page.on('pageerror', (e) => report.errors.push(`pageerror: ${e.message}`));
	page.on('console', (m) => { if (['error', 'warning'].includes(m.type())) report.console.push(m.text()); });
	await page.goto(`http://127.0.0.1:${server.address().port}/`, { waitUntil: 'load' });
	await page.waitForFunction(() => window.state !== 'loading');
	if (await page.evaluate(() => window.state) !== 'ready') throw new Error(await page.evaluate(() => window.error));
	report.model = await page.evaluate(() => window.model);
	for (const spec of shotsArg.split(',')) {
		const [name, time, azimuth, distance = '4', height = '0.9'] = spec.split(':');
		const view = [time, Number(azimuth), Number(distance), Number(height)];
		const box = await page.evaluate((v) => window.shoot(...v), view);
		const path = join(outDir, `${name}.png`);
		await page.locator('canvas').screenshot({ path });
		report.shots.push({ name, time, azimuth: Number(azimuth), distance: Number(distance), path, box });
	}
	report.ok = true;
} catch (e) {
	report.errors.push(`exception: ${e && e.stack ? e.stack : e}`);
} finally {
	if (browser) await browser.close();
	server.close();
}
console.log(JSON.stringify(report));
