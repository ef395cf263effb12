// Parse a .glb with three.js's GLTFLoader, play its animation, and report every node's world position.
//
// Run by tests/test_gltf.py as
//     node tests/clients/three_gltf_import.mjs FILE FPS FRAMES
// FRAMES: comma-separated frame indices (time = frame / FPS). Prints one JSON object on stdout;
// loader console errors and warnings are collected in "errors".
import { readFileSync } from 'node:fs';
import { AnimationMixer, LoopOnce, Vector3 } from 'three';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';

const [file, fps, framesArg] = process.argv.slice(2);
const report = { file, errors: [], animations: 0, duration: null, positions: {} };
const collect = (kind) => (...args) => report.errors.push(`${kind}: ${args.join(' ')}`);
console.error = collect('error');
console.warn = collect('warn');

const data = readFileSync(file);
const buffer = data.buffer.slice(data.byteOffset, data.byteOffset + data.byteLength);
new GLTFLoader().parse(buffer, '', (gltf) => {
	const scene = gltf.scene;
	report.animations = gltf.animations.length;
	report.duration = gltf.animations[0].duration;
	const mixer = new AnimationMixer(scene);
	const action = mixer.clipAction(gltf.animations[0]);
	action.setLoop(LoopOnce, 1);
	action.clampWhenFinished = true;
	action.play();
	for (const f of framesArg.split(',').map(Number)) {
		mixer.setTime(f / Number(fps));
		scene.updateMatrixWorld(true);
		const pos = {};
		scene.traverse((node) => {
			if (node.name) pos[node.name] = node.getWorldPosition(new Vector3()).toArray();
		});
		report.positions[f] = pos;
	}
	console.log(JSON.stringify(report));
}, (err) => {
	report.errors.push(`parse: ${err}`);
	console.log(JSON.stringify(report));
});
