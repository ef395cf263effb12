// Parse a BVH file with three.js's BVHLoader and report what three.js made of it.
//
// Run by tests/test_bvh_clients.py as
//     node tests/clients/three_import.mjs FILE [FRAMES]
// FRAMES is a comma-separated list of BVH frame indices at which to report the world
// position of every joint bone after playing the clip with an AnimationMixer. Prints one
// JSON object on stdout; loader console errors and warnings are collected in "errors".
import { readFileSync } from 'node:fs';
import { AnimationMixer, LoopOnce, Vector3 } from 'three';
import { BVHLoader } from 'three/examples/jsm/loaders/BVHLoader.js';

const [file, framesArg = ''] = process.argv.slice(2);
const report = { file, errors: [], bones: [], bone_count: 0, track_count: 0, duration: null, positions: {} };

const collect = (kind) => (...args) => report.errors.push(`${kind}: ${args.join(' ')}`);
console.error = collect('error');
console.warn = collect('warn');

try {
	const result = new BVHLoader().parse(readFileSync(file, 'utf8'));
	const bones = result.skeleton.bones;
	report.bones = bones.map((b) => b.name);
	report.bone_count = bones.length;
	report.track_count = result.clip.tracks.length;
	report.duration = result.clip.duration;
	report.frame_time = result.clip.tracks[0].times[1] - result.clip.tracks[0].times[0];

	const root = bones[0];
	const mixer = new AnimationMixer(root);
	// Play once and hold the last frame: a repeating clip wraps to frame 0 at its end.
	const action = mixer.clipAction(result.clip);
	action.setLoop(LoopOnce, 1);
	action.clampWhenFinished = true;
	action.play();
	const frames = framesArg ? framesArg.split(',').map(Number) : [];
	for (const f of frames) {
		mixer.setTime(result.clip.tracks[0].times[f]);
		root.updateMatrixWorld(true);
		const pos = {};
		for (const b of bones) {
			if (b.name !== 'ENDSITE') pos[b.name] = b.getWorldPosition(new Vector3()).toArray();
		}
		report.positions[String(f)] = pos;
	}
} catch (e) {
	report.errors.push(`exception: ${e && e.stack ? e.stack : e}`);
}
process.stdout.write(JSON.stringify(report));
