// Load VRM avatars with @pixiv/three-vrm in headless Chromium, play a VRM Animation on each with
// @pixiv/three-vrm-animation (createVRMAnimationClip), render them with three.js, and report where
// three-vrm puts every humanoid bone at the given times, with a screenshot of the canvas at each.
//
// Run by tests/test_vrm.py as
//     node tests/clients/vrm_check.mjs OUT_DIR ANIMATION.vrma TIMES AVATAR.vrm[,AVATAR.vrm...] [CHROMIUM]
// TIMES: comma-separated seconds. ANIMATION may instead be POSES.json, {time: {bone: {rotation, position}}}:
// VRM normalized poses as a VMC-to-page bridge gives them (tests/test_vmc.py), each set with
// vrm.humanoid.setNormalizedPose at its time; the hips' position is where the hips are, the page
// makes it relative to its avatar's rest, as setNormalizedPose takes it. A VRM 0.x avatar is turned to face +Z as apps do (VRMUtils.rotateVRM0).
// Writes OUT_DIR/<avatar index>_<time index>.png and prints one JSON object on stdout:
// {ok, errors, console, background,
//  avatars: [{file, metaVersion, name, bones, duration, tracks, positions: {time: {bone: xyz}}}]}.
// The page and its modules are served from memory and tests/clients/node_modules (page.route): no network.
import { readFile } from 'node:fs/promises';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { launchChromium } from './headless.mjs';

const [outDir, animation, timesArg, avatarsArg, executablePath = '/usr/bin/chromium'] = process.argv.slice(2);
const times = timesArg.split(',').map(Number);
const avatars = avatarsArg.split(',');
const modules = path.join(path.dirname(fileURLToPath(import.meta.url)), 'node_modules');
const BACKGROUND = [32, 48, 64];
const report = { ok: false, errors: [], console: [], background: BACKGROUND, avatars: [] };
const ORIGIN = 'http://dancesynth.test';

const page_html = `<!doctype html><html><head><meta charset="utf-8">
<script type="importmap">{"imports": {
  "three": "/node_modules/three/build/three.module.js",
  "three/addons/": "/node_modules/three/examples/jsm/",
  "@pixiv/three-vrm": "/node_modules/@pixiv/three-vrm/lib/three-vrm.module.js",
  "@pixiv/three-vrm-animation": "/node_modules/@pixiv/three-vrm-animation/lib/three-vrm-animation.module.js"}}
</script></head><body style="margin:0"><canvas id="view" width="360" height="480"></canvas>
<script type="module">
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { VRMLoaderPlugin, VRMUtils } from '@pixiv/three-vrm';
import { VRMAnimationLoaderPlugin, createVRMAnimationClip } from '@pixiv/three-vrm-animation';

const canvas = document.getElementById('view');
const renderer = new THREE.WebGLRenderer({ canvas, preserveDrawingBuffer: true });
renderer.setClearColor(new THREE.Color().setRGB(${BACKGROUND.map((c) => c / 255).join(',')}, THREE.SRGBColorSpace));
const camera = new THREE.PerspectiveCamera(35, canvas.width / canvas.height, 0.1, 50);
camera.position.set(0.8, 1.1, 4.6);   // in front of an avatar facing +Z, a little to its left
camera.lookAt(0, 0.9, 0);
const loader = new GLTFLoader();
loader.register((parser) => new VRMLoaderPlugin(parser));
loader.register((parser) => new VRMAnimationLoaderPlugin(parser));

window.loadAvatar = async (url, animationUrl) => {
  const scene = new THREE.Scene();
  scene.add(new THREE.HemisphereLight(0xffffff, 0x404040, 1.5));
  const sun = new THREE.DirectionalLight(0xffffff, 2.0);
  sun.position.set(1, 2, 3);
  scene.add(sun);
  const vrm = (await loader.loadAsync(url)).userData.vrm;
  if (!vrm) throw new Error(url + ': three-vrm found no VRM in it');
  if (vrm.meta.metaVersion === '0') VRMUtils.rotateVRM0(vrm);
  scene.add(vrm.scene);
  const bones = Object.keys(vrm.humanoid.humanBones).filter((b) => vrm.humanoid.getRawBoneNode(b));
  let setTime, clip = { duration: null, tracks: [] };
  if (animationUrl.endsWith('.json')) {
    const poses = await (await fetch(animationUrl)).json();
    const restHips = vrm.humanoid.normalizedRestPose.hips.position;
    setTime = (t) => {
      const pose = structuredClone(poses[String(t)]);
      if (pose.hips && pose.hips.position) pose.hips.position = pose.hips.position.map((v, i) => v - restHips[i]);
      vrm.humanoid.resetNormalizedPose();
      vrm.humanoid.setNormalizedPose(pose);
    };
  } else {
    const vrmAnimation = (await loader.loadAsync(animationUrl)).userData.vrmAnimations[0];
    clip = createVRMAnimationClip(vrmAnimation, vrm);
    const mixer = new THREE.AnimationMixer(vrm.scene);
    const action = mixer.clipAction(clip);
    action.setLoop(THREE.LoopOnce, 1);
    action.clampWhenFinished = true;
    action.play();
    setTime = (t) => mixer.setTime(t);
  }
  window.poseAt = (t) => {
    setTime(t);
    vrm.update(0);   // copies the normalized bones the clip or pose drives onto the avatar's own bones
    scene.updateMatrixWorld(true);
    renderer.render(scene, camera);
    const positions = {};
    for (const b of bones) {
      positions[b] = vrm.humanoid.getRawBoneNode(b).getWorldPosition(new THREE.Vector3()).toArray();
    }
    return positions;
  };
  return { metaVersion: vrm.meta.metaVersion, name: vrm.meta.name ?? vrm.meta.title, bones, duration: clip.duration,
    tracks: clip.tracks.length };
};
window.pageReady = true;
</script></body></html>`;

const animationPath = animation.endsWith('.json') ? '/dance.json' : '/dance.vrma';
const files = { [animationPath]: animation };
avatars.forEach((a, i) => { files[`/avatar${i}.vrm`] = a; });
const TYPES = { '.js': 'text/javascript', '.mjs': 'text/javascript', '.json': 'application/json' };

let browser;
try {
  browser = await launchChromium(executablePath);
  const page = await browser.newPage({ viewport: { width: 360, height: 480 } });
  page.setDefaultTimeout(30000);
  page.on('pageerror', (e) => report.errors.push(`pageerror: ${e.message}`));
  page.on('console', (m) => {
    if (['error', 'warning'].includes(m.type())) report.console.push(`${m.type()}: ${m.text()}`);
  });
  await page.route('**/*', async (route) => {
    const url = new URL(route.request().url());
    if (url.origin !== ORIGIN) return route.abort();
    if (url.pathname === '/') return route.fulfill({ body: page_html, contentType: 'text/html' });
    let file = files[url.pathname];
    if (!file && url.pathname.startsWith('/node_modules/')) {
      file = path.join(modules, decodeURIComponent(url.pathname.slice('/node_modules/'.length)));
      if (!file.startsWith(modules + path.sep)) return route.fulfill({ status: 403, body: '' });
    }
    try {
      const body = await readFile(file);
      return route.fulfill({ body, contentType: TYPES[path.extname(file)] ?? 'application/octet-stream' });
    } catch {
      return route.fulfill({ status: 404, body: 'not found' });
    }
  });
  await page.goto(`${ORIGIN}/`, { waitUntil: 'load' });
  await page.waitForFunction(() => window.pageReady === true);
  const canvas = page.locator('#view');
  for (let i = 0; i < avatars.length; i++) {
    const info = await page.evaluate(([a, b]) => window.loadAvatar(a, b), [`/avatar${i}.vrm`, animationPath]);
    const entry = { file: avatars[i], ...info, positions: {} };
    for (let k = 0; k < times.length; k++) {
      entry.positions[times[k]] = await page.evaluate((t) => window.poseAt(t), times[k]);
      await canvas.screenshot({ path: `${outDir}/${i}_${k}.png` });
    }
    report.avatars.push(entry);
  }
  report.ok = report.errors.length === 0;
} catch (e) {
  report.errors.push(`exception: ${e && e.stack ? e.stack : e}`);
} finally {
  if (browser) await browser.close().catch(() => {});
}
process.stdout.write(JSON.stringify(report));
