// The dancesynth page: ask the server for a dance, play the song, pose the character
// from the audio element's clock (so seeking and pausing keep motion and music in sync),
// and flash a ring on the floor on every music beat. The character is the skinned mesh the
// server sends as GLB; the stick figure (from the BVH, on the same rig) is the other view,
// and the only one for a rig without a mesh. Live, the character is its rest-pose GLB posed
// by the frames the server streams (the same rig, its joints named as the GLB's nodes).
import * as THREE from 'three';
import { BVHLoader } from 'three/addons/loaders/BVHLoader.js';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

const $ = (id) => document.getElementById(id);
const audio = $('audio');
const statusLine = $('status');
// What the page is doing, for people debugging it and for the browser test.
const state = (window.dancesynth = { state: 'loading', error: null, timings: {}, frames: 0, beats: 0, retries: 0,
	dance: null, view: null, playback: null, video: null });

function setStatus(text, isError = false) {
	statusLine.textContent = text;
	statusLine.classList.toggle('error', isError);
}

// A message about something the user did (a download, a video) that the playback line would overwrite:
// it stays until the next thing the user does.
function notify(text, isError = false) {
	const notice = $('notice');
	notice.textContent = text;
	notice.classList.toggle('error', isError);
}

// ---- scene ----------------------------------------------------------------------------
const canvas = $('view');
const renderer = new THREE.WebGLRenderer({ canvas, antialias: true });
renderer.setPixelRatio(Math.min(window.devicePixelRatio, 2));
const scene = new THREE.Scene();
scene.background = new THREE.Color();
const camera = new THREE.PerspectiveCamera(45, 1, 0.05, 100);
camera.position.set(1.5, 1.4, 2.5); // VIEWS['three-quarter'] from the target: the dancer fills most of the height
const controls = new OrbitControls(camera, canvas);
controls.target.set(0, 0.9, 0);
controls.update();
scene.add(new THREE.HemisphereLight(0xffffff, 0x404050, 2.0));
const sun = new THREE.DirectionalLight(0xffffff, 1.5);
sun.position.set(3, 6, 4);
scene.add(sun);
let grid = null; // lines every 0.5 m

// The page's palette (index.html's CSS variables, dark or light as the system asks) for the stage and timeline.
const palette = {};
function applyTheme() {
	const css = getComputedStyle(document.documentElement);
	for (const name of ['stage', 'grid', 'grid-minor', 'section-a', 'section-b', 'beat', 'bar', 'accent']) {
		palette[name] = css.getPropertyValue(`--${name}`).trim();
	}
	scene.background.set(palette.stage);
	if (grid) { scene.remove(grid); grid.dispose(); }
	grid = new THREE.GridHelper(10, 20, palette.grid, palette['grid-minor']);
	scene.add(grid);
}
applyTheme();
window.matchMedia('(prefers-color-scheme: light)').addEventListener('change', applyTheme);

const ring = new THREE.Mesh(
	new THREE.RingGeometry(0.55, 0.7, 64),
	new THREE.MeshBasicMaterial({ color: 0x4fc3f7, transparent: true, opacity: 0.15, side: THREE.DoubleSide }),
);
ring.rotation.x = -Math.PI / 2;
ring.position.y = 0.002;
scene.add(ring);

const figureMaterial = new THREE.MeshLambertMaterial({ color: 0xff8c1a });
const limbGeometry = new THREE.CylinderGeometry(1, 1, 1, 10); // scaled per bone
const jointGeometry = new THREE.SphereGeometry(1, 12, 8);

// What is on stage: { figures: { stick, character? }, beats, sections, duration, offset, result? }.
// A figure is { group, hips, mixer, action, duration, limbs } (limbs: the stick figure's cylinders).
let dance = null;

function resize() {
	const w = canvas.clientWidth, h = canvas.clientHeight;
	if (w && h && (canvas.width !== Math.round(w * renderer.getPixelRatio()) || camera.aspect !== w / h)) {
		renderer.setSize(w, h, false);
		camera.aspect = w / h;
		camera.updateProjectionMatrix();
	}
}

// A figure whose pose is set from the music clock: one animation, never played by the mixer's own clock.
function animated(group, hips, clip, limbs = []) {
	const mixer = new THREE.AnimationMixer(group);
	const action = mixer.clipAction(clip);
	action.setLoop(THREE.LoopOnce, 1);
	action.clampWhenFinished = true;
	action.play();
	return { group, hips, mixer, action, duration: clip.duration, limbs };
}

// A track is named "bone.property", and the mixer takes ':' and '.' for path separators: a rig's bone named
// "mixamorig:Hips" would never be found (the figure stood in its rest pose). Name the bones as the mixer reads them.
const mixerName = THREE.PropertyBinding.sanitizeNodeName;

function buildStick(bvhText) {
	const result = new BVHLoader().parse(bvhText);
	const bones = result.skeleton.bones;
	for (const bone of bones) bone.name = mixerName(bone.name);
	for (const track of result.clip.tracks) {
		const dot = track.name.lastIndexOf('.');
		track.name = mixerName(track.name.slice(0, dot)) + track.name.slice(dot);
	}
	const root = bones[0];
	const group = new THREE.Group();
	group.add(root);
	const limbs = [];
	for (const bone of bones) {
		const parent = bone.parent;
		if (!parent || !parent.isBone) continue;
		const length = bone.position.length();
		if (length < 1e-3) continue;
		const radius = bone.name === 'ENDSITE' ? 0.03 : Math.min(0.05, Math.max(0.02, length * 0.12));
		const mesh = new THREE.Mesh(limbGeometry, figureMaterial);
		mesh.scale.set(radius, length, radius);
		limbs.push({ mesh, bone, parent });
		group.add(mesh);
	}
	const head = bones.find((b) => /head/i.test(b.name));
	if (head) {
		const sphere = new THREE.Mesh(jointGeometry, figureMaterial);
		sphere.scale.setScalar(0.1);
		limbs.push({ mesh: sphere, bone: head, parent: null });
		group.add(sphere);
	}
	return animated(group, root, result.clip, limbs);
}

// A GLB's scene, its skeleton's root bone and its animations. The loader names nodes as the mixer reads
// them (mixerName), as buildStick names the bones: a BVH's clip of the same rig poses this scene.
async function loadModel(glbUrl) {
	const response = await fetch(glbUrl);
	if (!response.ok) await readJSON(response); // throws the server's message
	const gltf = await new GLTFLoader().parseAsync(await response.arrayBuffer(), '');
	let hips = null;
	gltf.scene.traverse((o) => {
		// A skinned mesh's bounds are those of its rest pose: never cull it as it dances away from them.
		if (o.isSkinnedMesh) { o.frustumCulled = false; hips = hips || o.skeleton.bones[0]; }
	});
	return { scene: gltf.scene, hips: hips || gltf.scene, animations: gltf.animations };
}

async function buildCharacter(glbUrl) {
	const model = await loadModel(glbUrl);
	if (!model.animations.length) throw new Error('the character has no animation');
	return animated(model.scene, model.hips, model.animations[0]);
}

let wantedFigure = 'character'; // what the user chose to see

// The figure shown: the character unless the stick figure is chosen or there is no character.
function shownFigure() {
	if (!dance) return null;
	return ($('figure').value === 'character' && dance.figures.character) || dance.figures.stick;
}

function showDance(next) {
	if (dance) for (const f of Object.values(dance.figures)) scene.remove(f.group);
	dance = next;
	for (const f of Object.values(dance.figures)) scene.add(f.group);
	updateView();
}

// Without a character (a rig without a mesh, a live one still loading) the stick figure only, until a
// dance with one brings back the choice made.
function offerFigures(hasCharacter) {
	$('figure').options[0].disabled = !hasCharacter;
	$('figure').value = hasCharacter ? wantedFigure : 'stick';
	updateView();
}

function updateView() {
	const shown = shownFigure();
	if (dance) for (const f of Object.values(dance.figures)) f.group.visible = f === shown;
	state.view = shown ? (shown === dance.figures.stick ? 'stick' : 'character') : null;
}

const _a = new THREE.Vector3(), _b = new THREE.Vector3(), _dir = new THREE.Vector3();
const _up = new THREE.Vector3(0, 1, 0);

function poseAt(fig, t) {
	// Set the action's time directly: the audio clock is the only clock.
	fig.action.paused = false;
	fig.action.enabled = true;
	fig.action.time = Math.min(Math.max(t, 0), Math.max(fig.duration - 1e-4, 0));
	fig.mixer.update(0);
	fig.group.updateMatrixWorld(true);
	for (const { mesh, bone, parent } of fig.limbs) {
		bone.getWorldPosition(_b);
		if (!parent) {
			mesh.position.copy(_b).addScaledVector(_up, 0.08);
			continue;
		}
		parent.getWorldPosition(_a);
		_dir.subVectors(_b, _a);
		const len = _dir.length();
		mesh.position.addVectors(_a, _b).multiplyScalar(0.5);
		if (len > 1e-6) mesh.quaternion.setFromUnitVectors(_up, _dir.divideScalar(len));
	}
	// The ring stays under the hips; the camera (unless the view is free) keeps its offset from where the
	// hips are on average over the moments around this one: it is there at once after a seek, and it
	// moves with a step before the step is made rather than after.
	fig.hips.getWorldPosition(_a);
	ring.position.x = _a.x;
	ring.position.z = _a.z;
	if ($('camera-view').value !== 'free') {
		const [x, z] = aimAt(fig, t) || [_a.x, _a.z];
		const dx = x - controls.target.x, dz = z - controls.target.z;
		controls.target.x += dx; controls.target.z += dz;
		camera.position.x += dx; camera.position.z += dz;
		const yaw = $('camera-view').value === 'follow' && followYaw(t);
		if (yaw !== false) { // the video's camera: a 3/4 view of her facing, turning slowly with it
			const [, up, away] = FOLLOW;
			camera.position.set(controls.target.x + away * Math.sin(yaw), controls.target.y + up,
				controls.target.z + away * Math.cos(yaw));
		}
	}
}

// The follow view's yaw at t (the server's, as the MP4's camera turns), or false where there is none.
const FOLLOW = [0, 0.5, Math.hypot(1.5, 2.5)]; // the three-quarter view's height and distance
function followYaw(t) {
	const cam = dance && dance.result && dance.result.camera;
	if (!cam || !cam.yaw.length) return false;
	const i = Math.min(Math.max(t * cam.rate_hz, 0), cam.yaw.length - 1);
	const a = Math.floor(i), b = Math.min(a + 1, cam.yaw.length - 1);
	return cam.yaw[a] + (cam.yaw[b] - cam.yaw[a]) * (i - a);
}

const AIM_S = 1.0; // the camera aims at the hips' mean place over this long before and after the moment

// The hips' path on the floor, as running sums over the clip's keyframes (its root position track).
function hipsPath(fig) {
	const track = fig.action.getClip().tracks.find((tr) => tr.name.endsWith('.position'));
	if (!track || !fig.hips.parent) return null;
	fig.group.updateMatrixWorld(true);
	const toWorld = fig.hips.parent.matrixWorld; // still: only the bones move
	const n = track.times.length, v = track.values;
	const cx = new Float64Array(n + 1), cz = new Float64Array(n + 1);
	const p = new THREE.Vector3();
	for (let i = 0; i < n; i++) {
		p.set(v[3 * i], v[3 * i + 1], v[3 * i + 2]).applyMatrix4(toWorld);
		cx[i + 1] = cx[i] + p.x;
		cz[i + 1] = cz[i] + p.z;
	}
	return { times: track.times, cx, cz };
}

function aimAt(fig, t) {
	if (fig.path === undefined) fig.path = hipsPath(fig);
	const path = fig.path;
	if (!path || !path.times.length) return null;
	const n = path.times.length;
	const a = Math.min(lastAtOrBefore(path.times, t - AIM_S) + 1, n - 1);
	const b = Math.max(Math.min(lastAtOrBefore(path.times, t + AIM_S) + 1, n), a + 1);
	return [(path.cx[b] - path.cx[a]) / (b - a), (path.cz[b] - path.cz[a]) / (b - a)];
}

// The view presets: where the camera stands from the dancer (it follows her), or free (it stays put).
const VIEWS = { 'three-quarter': [1.5, 0.5, 2.5], front: [0, 0.45, 2.9], side: [2.9, 0.45, 0] };

function chooseView() {
	const offset = VIEWS[$('camera-view').value] || ($('camera-view').value === 'follow' && VIEWS['three-quarter']);
	if (offset) camera.position.set(controls.target.x + offset[0], controls.target.y + offset[1], controls.target.z + offset[2]);
	controls.update();
}

// Where the dancer is on the stage (for the browser test): the box of the shown figure's bones on screen, as
// shares of the canvas from its top left.
window.dancesynthFrame = () => {
	const fig = shownFigure();
	if (!fig) return null;
	let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
	fig.group.traverse((o) => {
		if (!o.isBone) return;
		o.getWorldPosition(_b).project(camera);
		x0 = Math.min(x0, _b.x); x1 = Math.max(x1, _b.x); y0 = Math.min(y0, _b.y); y1 = Math.max(y1, _b.y);
	});
	return { left: (x0 + 1) / 2, right: (x1 + 1) / 2, top: (1 - y1) / 2, bottom: (1 - y0) / 2, height: (y1 - y0) / 2,
		view_yaw: Math.atan2(camera.position.x - controls.target.x, camera.position.z - controls.target.z) };
};

// Index of the last value at or before t in a sorted list (binary search), -1 if none.
function lastAtOrBefore(values, t) {
	let lo = 0, hi = values.length - 1, found = -1;
	while (lo <= hi) {
		const mid = (lo + hi) >> 1;
		if (values[mid] <= t) { found = mid; lo = mid + 1; } else hi = mid - 1;
	}
	return found;
}

function frame() {
	resize();
	if (live && live.t0 !== null) {
		const now = live.ctx.currentTime;
		live.time = live.start + now - live.t0;
		state.live.time = live.time;
		// Starved: the music plays a moment whose motion has not arrived (the delay was too short).
		if (now > live.t0 && live.last !== null) {
			state.live.playing_s += now - live.last;
			const ready = live.base === null ? -Infinity : (live.base + live.rows.length) / live.fps;
			state.live.motion_until_s = ready;
			if (live.time > ready) state.live.starved_s += now - live.last;
		}
		live.last = now;
	}
	const fig = shownFigure();
	if (fig) {
		const t = live ? Math.max(live.time, 0) : audio.currentTime || 0;
		poseAt(fig, t - (dance.offset || 0)); // a live figure holds only the last part of the stream
		const i = lastAtOrBefore(dance.beats, t);
		const since = i >= 0 ? t - dance.beats[i] : Infinity;
		const pulse = Math.exp(-since / 0.12); // 1 on the beat, fading over ~0.3 s
		ring.material.opacity = 0.15 + 0.8 * pulse;
		ring.material.color.setHSL(0.55 - 0.1 * pulse, 0.9, 0.45 + 0.3 * pulse);
		ring.scale.setScalar(1 + 0.25 * pulse);
		if (!live) followPlayback();
	}
	controls.update();
	renderer.render(scene, camera);
	drawTimeline();
	requestAnimationFrame(frame);
}

// ---- the timeline: sections, bars and beats under the player; click or drag to seek --------
const timeline = $('timeline');

function drawTimeline() {
	const w = timeline.clientWidth, h = timeline.clientHeight, ratio = window.devicePixelRatio || 1;
	if (timeline.width !== Math.round(w * ratio) || timeline.height !== Math.round(h * ratio)) {
		timeline.width = Math.round(w * ratio);
		timeline.height = Math.round(h * ratio);
	}
	const g = timeline.getContext('2d');
	g.setTransform(ratio, 0, 0, ratio, 0, 0);
	g.clearRect(0, 0, w, h);
	const on = dance && dance.result && dance.duration > 0 && !live;
	state.timeline = on ? { beats: dance.beats.length, bars: dance.downbeats.length, sections: dance.sections.length } : null;
	if (!on) return;
	const x = (t) => (t / dance.duration) * w;
	dance.sections.forEach((s, i) => {
		const end = i + 1 < dance.sections.length ? dance.sections[i + 1].start_s : dance.duration;
		g.fillStyle = palette[i % 2 ? 'section-b' : 'section-a'];
		g.fillRect(x(s.start_s), 0, x(end) - x(s.start_s), h);
	});
	g.fillStyle = palette.beat;
	for (const t of dance.beats) g.fillRect(x(t), h - 7, 1, 7);
	g.fillStyle = palette.bar;
	for (const t of dance.downbeats) g.fillRect(x(t), h - 16, 1.5, 16);
	g.fillStyle = palette.accent;
	if (span) {
		g.globalAlpha = 0.35;
		g.fillRect(x(span.start), 0, x(span.end) - x(span.start), h);
		g.globalAlpha = 1;
	}
	g.fillRect(x(audio.currentTime || 0) - 1, 0, 2, h);
	timeline.setAttribute('aria-valuemax', dance.duration.toFixed(1));
	timeline.setAttribute('aria-valuenow', (audio.currentTime || 0).toFixed(1));
	timeline.setAttribute('aria-valuetext', state.playback ? state.playback.text : '');
}

function seekTo(t) {
	if (!dance || !dance.result || live) return;
	audio.currentTime = Math.min(Math.max(t, 0), Math.max(dance.duration - 0.05, 0));
}

// A click or drag seeks; with Shift held, a drag selects the span to re-dance (on beats).
timeline.addEventListener('pointerdown', (ev) => {
	const at = (e) => (e.offsetX / timeline.clientWidth) * (dance ? dance.duration : 0);
	const anchor = at(ev);
	const act = ev.shiftKey ? (e) => setSpan(anchor, at(e)) : (e) => seekTo(at(e));
	act(ev);
	timeline.setPointerCapture(ev.pointerId);
	timeline.onpointermove = act;
	timeline.onpointerup = () => { timeline.onpointermove = timeline.onpointerup = null; };
});

// Keys, as video players have them: space or K plays and pauses, J and L go 10 s back and on, the arrows
// to the previous or next beat (with Shift, bar). Not while typing in a field or choosing in a menu.
document.addEventListener('keydown', (ev) => {
	if (!dance || !dance.result || live || ev.ctrlKey || ev.metaKey || ev.altKey) return;
	if (ev.target.closest && ev.target.closest('input, select, textarea, button, summary, a')) return;
	const t = audio.currentTime || 0;
	const marks = ev.shiftKey ? dance.downbeats : dance.beats;
	const key = ev.key.length === 1 ? ev.key.toLowerCase() : ev.key;
	if (key === ' ' || key === 'k') {
		if (audio.paused) audio.play().catch(() => {}); else audio.pause();
	} else if (key === 'j' || key === 'l') {
		seekTo(t + (key === 'l' ? 10 : -10));
	} else if (key === '[') { // the span to re-dance starts here (and ends a bar on, if it ended before)
		setSpan(t, span && span.end > t + 0.1 ? span.end : t + barLength());
	} else if (key === ']') { // ... or ends here
		setSpan(span && span.start < t - 0.1 ? span.start : t - barLength(), t);
	} else if (key === 'ArrowRight' || key === 'ArrowLeft') {
		const i = lastAtOrBefore(marks, t + 1e-3);
		const next = key === 'ArrowRight' ? marks[i + 1] : marks[Math.max(t - (marks[i] ?? 0) < 0.15 ? i - 1 : i, 0)];
		if (next === undefined) return;
		seekTo(next);
	} else {
		return;
	}
	ev.preventDefault();
});

// ---- editing: re-dance a span of the dance on stage, undo ------------------------------
// The span (seconds, on the dance's beats) is chosen on the timeline (Shift+drag), with the [ and ] keys,
// or as the 4 bars from the bar playing; the server dances it again and joins it to the rest, which stays
// as it was. Each edit is a new dance; Undo puts the one before back on stage (its figures are kept here).
const edits = []; // the dances edits replaced, newest last: { stage, info }
const EDITS_KEPT = 10;
let span = null; // { start, end }

const nearestBeat = (t) => dance.beats.reduce((best, b) => (Math.abs(b - t) < Math.abs(best - t) ? b : best),
	dance.beats[0]);
const barLength = () => (dance && dance.downbeats.length > 1
	? (dance.downbeats[dance.downbeats.length - 1] - dance.downbeats[0]) / (dance.downbeats.length - 1) : 2);

function setSpan(a, b) {
	if (!dance || !dance.result || live || !dance.beats.length) return;
	const [start, end] = [nearestBeat(Math.min(a, b)), nearestBeat(Math.max(a, b))];
	span = end > start ? { start, end } : null;
	if (span) $('edit-panel').open = true; // a span chosen on the timeline or by key: show what can be done with it
	showSpan();
}

function showSpan() {
	const beats = span ? dance.beats.filter((b) => b >= span.start - 1e-3 && b <= span.end + 1e-3).length - 1 : 0;
	$('span').textContent = span ? `${clock(span.start)}–${clock(span.end)} (${beats} beats)`
		: 'none yet: Shift+drag the timeline';
	$('undo').disabled = !edits.length;
	state.edit = { span, undo: edits.length };
}

function barsFromHere(n = 4) {
	if (!dance || !dance.result) return;
	const t = audio.currentTime || 0;
	const bars = dance.downbeats.length ? dance.downbeats : dance.beats.filter((_, i) => i % 4 === 0);
	const i = Math.max(lastAtOrBefore(bars, t + 1e-3), 0);
	setSpan(bars[i], bars[i + n] ?? dance.beats[dance.beats.length - 1]);
}

async function redance(ev) {
	ev.preventDefault();
	if (!dance || !dance.result || live) return;
	if (!span) {
		setStatus('Select a span first: Shift+drag on the timeline, the [ and ] keys, or "4 bars from here".', true);
		return;
	}
	const form = new FormData();
	form.append('start_s', span.start.toFixed(4));
	form.append('end_s', span.end.toFixed(4));
	for (const [field, id] of [['seed', 'edit-seed'], ['style', 'edit-style'], ['motif', 'edit-motif']]) {
		if ($(id).value.trim()) form.append(field, $(id).value.trim());
	}
	$('redance').disabled = true;
	state.state = 'dancing';
	setStatus('Re-dancing the span…');
	const t0 = performance.now();
	try {
		const result = await postForm(dance.result.redance_url, form, 'Re-dancing the span…');
		state.timings.redance_ms = performance.now() - t0;
		const figures = await buildFigures(result);
		edits.push({ stage: dance, info: $('info').textContent });
		if (edits.length > EDITS_KEPT) edits.shift();
		const from = Math.max(span.start - barLength(), 0);
		present(result, figures, true);
		seekTo(from); // watch the new moves come in
		audio.play().catch(() => {});
	} catch (err) {
		state.state = 'error';
		state.error = String(err.message || err);
		setStatus(`Could not re-dance the span: ${state.error}`, true);
	} finally {
		$('redance').disabled = false;
	}
}

function undo() {
	const last = edits.pop();
	if (!last || live) return;
	present(last.stage.result, last.stage.figures, true);
	$('info').textContent = last.info;
}

// ---- the status line follows the music -------------------------------------------------
function clock(t) {
	const m = Math.floor(t / 60);
	return `${m}:${(t - 60 * m).toFixed(1).padStart(4, '0')}`;
}

// Where the song is (time, beat, section) and whether it plays; the status line says so as it changes.
function followPlayback() {
	if (!dance || !dance.result || state.state !== 'ready') return;
	const t = audio.currentTime || 0;
	const mode = audio.ended ? 'finished' : !audio.paused ? 'playing' : t > 0 ? 'paused' : 'ready';
	const beat = lastAtOrBefore(dance.beats, t) + 1;
	const section = lastAtOrBefore(dance.sections.map((s) => s.start_s), t) + 1;
	const where = [`${clock(t)} / ${clock(dance.duration)}`,
		beat ? `beat ${beat} of ${dance.beats.length}` : 'before the first beat'];
	if (section && dance.sections.length > 1) {
		where.push(`section ${section} of ${dance.sections.length} (${dance.sections[section - 1].level} level)`);
	} else if (section) {
		where.push(`one section (${dance.sections[0].level} level)`);
	}
	const text = {
		ready: `Ready: press play (${clock(dance.duration)}, ${dance.beats.length} beats)`,
		playing: `Playing ${where.join(' · ')}`,
		paused: `Paused at ${where.join(' · ')}`,
		finished: `Finished: ${clock(dance.duration)} danced to ${dance.beats.length} beats — press play to watch again`,
	}[mode];
	state.playback = { state: mode, time: t, beat, section, text };
	if (statusLine.textContent !== text) setStatus(text);
}

// ---- talking to the server -------------------------------------------------------------
async function readJSON(response) {
	let body = null;
	try { body = await response.json(); } catch { body = null; }
	if (!response.ok) {
		const error = new Error((body && body.error) || `${response.status} ${response.statusText}`);
		error.status = response.status;
		throw error;
	}
	return body;
}

async function getJSON(url, options) {
	return readJSON(await fetch(url, options));
}

const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

// A busy server answers 503 (or 429) with Retry-After: wait that long, plus a little so that
// pages told the same do not all come back at once, and ask again, for at most RETRY_FOR_MS.
// onWait(ms) is told before each wait, onWait(0) when asking again.
const RETRY_FOR_MS = 300000;

async function fetchRetrying(url, options, onWait) {
	const giveUp = performance.now() + RETRY_FOR_MS;
	for (let tries = 1; ; tries++) {
		const response = await fetch(url, options);
		const wait = Number(response.headers.get('Retry-After')) * 1000 * (1 + 0.25 * Math.random());
		if (![429, 503].includes(response.status) || !(wait > 0) || performance.now() + wait > giveUp) {
			return readJSON(response);
		}
		state.retries = tries;
		onWait(wait);
		await sleep(wait);
		onWait(0); // asking again
	}
}

// POST a form, saying ``doing`` while the server works and how long a busy server asks the page to wait.
function postForm(url, form, doing) {
	return fetchRetrying(url, { method: 'POST', body: form }, (wait) => setStatus(wait
		? `The server is busy; asking again in ${Math.round(wait / 1000)} s…` : doing));
}

const postDance = (form) => postForm('/api/dance', form, 'Listening to the music and choreographing…');

let characterInfo = {}; // the built-in characters by name: { name, description, mesh, joints }

// A character's name in the menus: a rig without a mesh dances as a stick figure.
const characterLabel = (c) => (c.mesh ? c.name : `${c.name} rig (stick figure)`);

// The genres each engine can dance here (null: any), and each style's genre: the menus offer only what works.
const engineGenres = {};
const styleGenre = {};

function fitChoices() {
	const genres = engineGenres[$('engine').value];
	for (const option of $('style').options) {
		option.disabled = Boolean(option.value && genres && !genres.includes(styleGenre[option.value]));
	}
	if ($('style').selectedOptions[0] && $('style').selectedOptions[0].disabled) $('style').value = '';
	const genre = styleGenre[$('style').value];
	for (const option of $('engine').options) {
		const only = engineGenres[option.value];
		option.disabled = Boolean(genre && only && !only.includes(genre));
		option.title = option.title.replace(/ \(learned only .*\)$/, '') +
			(option.disabled ? ` (learned only ${only.join(', ')})` : '');
	}
}

async function loadChoices() {
	const [songs, styles, engines, characters, limits] = await Promise.all(
		['/api/songs', '/api/styles', '/api/engines', '/api/characters', '/api/limits'].map((url) => getJSON(url)));
	state.limits = limits;
	$('limits').textContent = `(up to ${limits.max_upload_mb} MB, ${limits.max_song_minutes} min; or drop it on the stage)`;
	for (const s of songs.songs) $('song').add(new Option(s.title, s.name));
	for (const s of styles.styles) {
		const tempo = `${Math.round(s.tempo_min_bpm)}-${Math.round(s.tempo_max_bpm)} bpm`;
		$('style').add(new Option(`${s.name} (${s.genre}, ${tempo})`, s.name));
		$('edit-style').add(new Option(`${s.name} (${s.genre}, ${tempo})`, s.name));
		styleGenre[s.name] = s.genre;
	}
	for (const e of engines.engines) {
		const option = new Option(e.name + (e.name === engines.default ? ' (default)' : ''), e.name);
		option.title = e.description;
		$('engine').add(option);
		engineGenres[e.name] = e.genres;
	}
	$('engine').value = engines.default;
	for (const c of characters.characters) {
		for (const menu of ['character', 'live-character']) {
			const option = new Option(characterLabel(c), c.name);
			option.title = c.description;
			$(menu).add(option);
		}
	}
	$('character').add(new Option('your own file (.glb, .gltf, .vrm, .bvh)…', OWN));
	$('character').value = $('live-character').value = characters.default;
	characterInfo = Object.fromEntries(characters.characters.map((c) => [c.name, c]));
	if (songs.songs.length) $('song').value = songs.songs[0].name;
	fitChoices();
}

const PREVIOUS = 'Still on stage, the previous dance: ';

// The stick figure of a dance's BVH and, where it has one, the character's mesh.
async function buildFigures(result) {
	const figures = { stick: buildStick(result.bvh) };
	if (result.glb_url) {
		setStatus('Dressing the character…');
		figures.character = await buildCharacter(result.glb_url);
	}
	return figures;
}

// Put a dance on stage: its figures, marks, downloads and info line; the song is loaded from its start
// unless ``sameSong`` (an edit or an undo: the music plays on where it is).
function present(result, figures, sameSong = false) {
	stopLive();
	if (videoJob) cancelVideo(videoJob); // the video of the dance that leaves the stage is not wanted
	showDance({ figures, beats: result.beats, downbeats: result.downbeats || [], sections: result.sections,
		duration: result.duration_s, result });
	offerFigures(Boolean(figures.character));
	offerDownloads(result);
	if (!sameSong) {
		audio.pause();
		audio.src = result.audio_url;
		audio.currentTime = 0;
	}
	state.frames = result.frames;
	state.beats = result.beats.length;
	state.dance = { id: result.dance_id, engine: result.engine, character: result.character, mesh: result.mesh,
		style: result.style, joints: result.joints, beats: result.beats, downbeats: result.downbeats,
		edits: result.edits || [], camera: result.camera };
	const edited = (result.edits || []).length;
	$('info').textContent = `${result.style} at ${result.tempo_bpm.toFixed(1)} bpm, ${result.beats.length} beats, ` +
		`${result.duration_s.toFixed(1)} s · ${result.engine} engine · ${result.character}` +
		(result.mesh ? '' : ' rig') + (result.default_tempo ? ' · no clear beat: a steady default tempo' : '') +
		(result.form && result.form.length > 1 ? ' · form ' + result.form.map((s) => s.label).join(' ') +
			' (' + result.form.filter((s) => s.replays !== null && s.replays !== undefined).length +
			' sections danced again)' : '') +
		(edited ? ` · ${edited} span${edited > 1 ? 's' : ''} re-danced` : '');
	state.state = 'ready';
	$('edit-panel').hidden = false;
	showSpan();
	followPlayback();
}
const OWN = ':own'; // the Character menu's "your own file" (no built-in is named so)

// "Your own file" shows where to choose it (and its bone map, for a rig whose bones have unusual names).
function showOwnCharacter() {
	$('own-character').hidden = $('character').value !== OWN;
	if ($('character').value === OWN && !$('character-file').files.length) $('character-file').focus();
}

async function requestDance(event) {
	event.preventDefault();
	notify('');
	const form = new FormData();
	const file = $('file').files[0];
	if (file && !$('song').value) form.append('audio', file);
	else if ($('song').value) form.append('song', $('song').value);
	else if (file) form.append('audio', file);
	else { setStatus('Pick a song or choose an audio file.', true); return; }
	for (const field of ['style', 'seed', 'engine']) form.append(field, $(field).value);
	if ($('character').value !== OWN) form.append('character', $('character').value);
	else if ($('character-file').files.length) {
		form.append('character_file', $('character-file').files[0]);
		if ($('bone-map').files.length) form.append('bone_map', $('bone-map').files[0]);
	} else { setStatus('Choose your character file (.glb, .gltf, .vrm or .bvh), or pick a built-in character.', true); return; }
	const sent = [...form.values()].filter((v) => v instanceof File);
	const bytes = sent.reduce((sum, f) => sum + f.size, 0);
	if (bytes > state.limits.max_upload_mb * 2 ** 20) {
		setStatus(`${sent.map((f) => f.name).join(' and ')} ${sent.length > 1 ? 'are' : 'is'} ` +
			`${(bytes / 2 ** 20).toFixed(1)} MB; this server takes files up to ${state.limits.max_upload_mb} MB (together): ` +
			'cut or compress it first.', true);
		return;
	}
	$('dance').disabled = true;
	state.state = 'dancing';
	setStatus('Listening to the music and choreographing…');
	const t0 = performance.now();
	try {
		const result = await postDance(form);
		state.timings.dance_ms = performance.now() - t0;
		const figures = await buildFigures(result);
		state.timings.figures_ms = performance.now() - t0 - state.timings.dance_ms;
		edits.length = 0; // a new dance: the edits of the one before are not undone into it
		span = null;
		present(result, figures);
		audio.play().catch(() => {}); // browsers may refuse autoplay; the play button works
	} catch (err) {
		state.state = 'error';
		state.error = String(err.message || err);
		setStatus(`Could not dance: ${state.error}`, true);
		// What is on stage is not the dance asked for: say so, rather than let it pass for the result.
		if (dance && dance.result && !$('info').textContent.startsWith(PREVIOUS)) {
			$('info').textContent = PREVIOUS + $('info').textContent;
		}
	} finally {
		$('dance').disabled = false;
	}
}

// ---- downloads -------------------------------------------------------------------------
// A 10-minute song's video takes minutes on a small server, and a render may wait for others: give up
// only after RENDER_WAIT_MS in all or when a render has not moved on for STALL_MS.
const RENDER_WAIT_MS = 60 * 60 * 1000;
const STALL_MS = 2 * 60 * 1000;
const POLL_MS = 500;

// The links to the dance's files, or none (null: a live dance has no files).
function offerDownloads(result) {
	for (const kind of ['bvh', 'glb', 'vrma', 'fbx']) {
		const link = $(`dl-${kind}`);
		if (result) link.href = result.downloads[kind];
		else link.removeAttribute('href');
		link.dataset.made = '';
		link.setAttribute('aria-disabled', String(!result));
	}
	state.video = null;
	$('dl-mp4').disabled = !result;
	$('dl-mp4').textContent = 'MP4';
	$('dl-mp4').title = '';
}

// The server renders the MP4 with the song (a while for a long song): start it, show how far it has
// got on the button (with an estimate of the time left), and download it when it is done. Only the
// dance on stage gets its video: dancing another one cancels the render, and so does a second click.
let videoJob = null; // { result, url, cancelled }

async function downloadVideo() {
	const result = dance && dance.result;
	if (!result) return;
	if (videoJob && videoJob.result === result) { cancelVideo(videoJob); return; }
	notify('');
	const button = $('dl-mp4');
	const url = `${result.video_url}?figure=${state.view === 'stick' ? 'stick' : 'character'}`;
	const job = (videoJob = { result, url, cancelled: false });
	const current = () => !job.cancelled && dance && dance.result === result;
	const show = (text) => { if (current()) button.textContent = text; };
	button.title = 'click again to cancel';
	state.video = { state: 'starting', progress: 0, error: null };
	show('MP4: starting…');
	try {
		const giveUp = performance.now() + RENDER_WAIT_MS;
		let status = await fetchRetrying(url, { method: 'POST' }, (wait) =>
			show(wait ? `MP4: the server is busy, again in ${Math.round(wait / 1000)} s` : 'MP4: starting…'));
		let moved = { at: performance.now(), key: '' };
		while (['queued', 'rendering'].includes(status.state)) {
			if (!current()) { if (!job.cancelled) cancelVideo(job); return; } // another dance is on stage now
			state.video = { state: status.state, progress: status.progress, error: null, eta_s: status.eta_s };
			const left = status.eta_s === null || status.eta_s === undefined ? '' : `, ~${Math.ceil(status.eta_s)} s left`;
			show(status.state === 'queued' ? 'MP4: waiting for a turn… (cancel)' :
				`MP4: ${Math.round(100 * status.progress)}%${left} (cancel)`);
			const key = `${status.state} ${status.frames_done}`;
			if (key !== moved.key) moved = { at: performance.now(), key };
			if (status.state === 'rendering' && performance.now() - moved.at > STALL_MS) {
				throw new Error('the render stopped moving on; try again later');
			}
			if (performance.now() > giveUp) throw new Error('the video took too long; try again later');
			await sleep(POLL_MS);
			status = await getJSON(url);
		}
		if (!current()) return;
		if (status.state !== 'done') throw new Error(status.error || `the video ended as ${status.state}`);
		state.video = { state: 'done', progress: 1, error: null, url: status.url, dance_id: result.dance_id };
		show('MP4 ✓');
		button.title = '';
		const link = document.createElement('a');
		link.href = status.url;
		link.download = '';
		link.click();
	} catch (err) {
		if (!current()) return;
		state.video = { state: 'error', progress: 0, error: String(err.message || err) };
		if (err.status === 404) { danceGone(); return; }
		show('MP4 (failed: try again)');
		button.title = state.video.error;
	} finally {
		if (videoJob === job) videoJob = null;
	}
}

function cancelVideo(job) {
	job.cancelled = true;
	fetch(job.url, { method: 'DELETE' }).catch(() => {});
	if (dance && dance.result === job.result) {
		state.video = { state: 'cancelled', progress: 0, error: null };
		$('dl-mp4').textContent = 'MP4';
		$('dl-mp4').title = '';
		notify('The video was cancelled.');
	}
}

// The server keeps only its latest dances: one it has let go of cannot be downloaded any more.
function danceGone() {
	offerDownloads(null);
	state.video = { state: 'gone', progress: 0, error: null };
	notify('The server keeps only its latest dances and has let this one go: press Dance to make it again ' +
		'(its files come with it).', true);
}

// A file link is checked before the browser saves it: a dance the server has let go of would otherwise
// save nothing and say nothing.
async function downloadFile(event) {
	const link = event.currentTarget;
	if (link.dataset.checked === 'yes') { link.dataset.checked = ''; return; } // checked: let the browser save it
	event.preventDefault();
	if (link.getAttribute('aria-disabled') === 'true' || !link.href) return;
	const slow = link.id === 'dl-fbx' && !link.dataset.made;
	if (slow) notify('Making the FBX (Blender converts the dance on the server: a few seconds)…');
	try {
		const response = await fetch(link.href, { method: 'HEAD' });
		if (response.status === 404) { danceGone(); return; }
		if (!response.ok) {
			const body = await fetch(link.href).then((r) => r.json()).catch(() => ({}));
			throw new Error(body.error || `HTTP ${response.status}`);
		}
		if (slow) { notify(''); link.dataset.made = 'yes'; }
		link.dataset.checked = 'yes';
		link.click();
	} catch (err) {
		notify(`Could not download the ${link.textContent}: ${err.message || err}`, true);
	}
}

// ---- live mode: the server dances to a stream; the page plays its audio after a delay ------
// The server relays the stream's audio as 16-bit PCM, the BVH hierarchy once (the chosen
// character's rig), and every segment's frames and beats. Audio is scheduled with Web Audio
// `delay_s` after it arrives, the delay the double buffer needs for the motion of each moment
// to be here before it is heard. The stick figure is built from the frames kept; a character
// with a mesh is its rest-pose GLB posed by the same animation.
// A capture (a tab's sound or the microphone) goes the other way too: the page sends what it hears
// over the same socket (capture.js) and the server dances to it. The sound comes back like a
// stream's and keeps the dance's clock, heard only where the tab's own playback was muted for it
// (else the music would sound twice, or a microphone would hear itself).
let live = null;
const KEEP_S = 60; // the live figure holds the last minute of motion
const CAPTURE_NAMES = { tab: "the tab's sound", mic: 'the microphone' };
const QUIET = { echoCancellation: false, noiseSuppression: false, autoGainControl: false }; // music, not speech

function stopLive() {
	state.capturing = null; // a capture still waiting for the user's choice is not started
	$('engine').disabled = false;
	$('live-pause').hidden = true;
	if (!live) return;
	live.ws.onmessage = live.ws.onclose = null;
	live.ws.close();
	if (live.capture) live.capture.stream.getTracks().forEach((t) => t.stop());
	live.ctx.close().catch(() => {});
	live = null;
}

function liveAudio(buffer) {
	const pcm = new Int16Array(buffer);
	if (!pcm.length) return;
	if (live.t0 === null) live.t0 = live.ctx.currentTime + live.delay;
	const b = live.ctx.createBuffer(1, pcm.length, live.sr);
	const ch = b.getChannelData(0);
	for (let i = 0; i < pcm.length; i++) ch[i] = pcm[i] / 32768;
	const src = live.ctx.createBufferSource();
	src.buffer = b;
	src.connect(live.out);
	src.start(Math.max(live.t0 + live.samples / live.sr, live.ctx.currentTime));
	live.samples += pcm.length;
	state.live.heard_s = live.samples / live.sr;
}

function liveFrames(startFrame, rows) {
	if (live.base === null) live.base = startFrame; // a late viewer starts from the backlog
	live.rows.push(...rows);
	const drop = live.rows.length - Math.round(KEEP_S * live.fps);
	if (drop > 0) { live.rows.splice(0, drop); live.base += drop; }
	const text = `${live.hierarchy}\nMOTION\nFrames: ${live.rows.length}\nFrame Time: ${(1 / live.fps).toFixed(8)}\n` +
		live.rows.join('\n') + '\n';
	live.stick = buildStick(text);
	showLive();
	state.live.frames = startFrame + rows.length;
}

// The live figures: the stick figure of the frames kept and, once its GLB is here, the character posed by
// the same animation (the tracks are named as the GLB's nodes, both sanitised by mixerName).
function showLive() {
	if (!live.stick) return;
	const figures = { stick: live.stick };
	const clip = live.stick.action.getClip();
	if (live.model && !live.model.checked) {
		live.model.checked = true;
		const missing = clip.tracks.map((t) => t.name.slice(0, t.name.lastIndexOf('.')))
			.filter((name) => !live.model.scene.getObjectByName(name));
		if (missing.length) liveModelFailed(`its skeleton has no ${missing.slice(0, 3).join(', ')}`);
	}
	if (live.model) figures.character = animated(live.model.scene, live.model.hips, clip);
	showDance({ figures, offset: live.base / live.fps, beats: live.beats, sections: [] });
}

// The character could not be shown: the stick figure dances on, and the info line says why.
function liveModelFailed(why) {
	live.model = null;
	state.live.model = `error: ${why}`;
	offerFigures(false);
	$('info').textContent = `Live: the stick figure on the ${live.character} rig (the ${live.character} ` +
		`could not be shown: ${why})`;
}

function startLive(event) {
	event.preventDefault();
	notify('');
	stopLive();
	audio.pause();
	const url = $('live-url').value.trim();
	if (!url) { setStatus('Give the URL of a stream (http or https).', true); return; }
	openLive({ url }, new AudioContext(), null);
	setStatus('Connecting to the stream…');
}

// Dance to a tab's sound or the microphone. The browser asks the user first; the audio context is made
// here, in the click, so the browser lets it play.
async function startCapture(kind) {
	notify('');
	stopLive();
	audio.pause();
	const what = CAPTURE_NAMES[kind];
	const media = navigator.mediaDevices;
	const getter = kind === 'tab' ? 'getDisplayMedia' : 'getUserMedia';
	if (!media || !media[getter] || !window.AudioWorkletNode) {
		setStatus(`This browser cannot share ${what} with the page` + (window.isSecureContext ? '.' :
			': browsers allow it only on https:// pages and on localhost.'), true);
		return;
	}
	const ctx = new AudioContext();
	const token = (state.capturing = {});
	let stream;
	try {
		setStatus(kind === 'tab' ? 'Pick the tab that plays the music, with its audio shared…' :
			'Allow the microphone…');
		stream = kind === 'tab'
			? await media.getDisplayMedia({ video: true, audio: { ...QUIET, suppressLocalAudioPlayback: true },
				preferCurrentTab: false, selfBrowserSurface: 'exclude', systemAudio: 'include' })
			: await media.getUserMedia({ audio: QUIET });
	} catch (err) {
		ctx.close().catch(() => {});
		if (state.capturing !== token) return;
		state.capturing = null;
		setStatus(captureRefused(kind, err), true);
		return;
	}
	const track = stream.getAudioTracks()[0];
	const surface = stream.getVideoTracks().map((t) => t.getSettings().displaySurface)[0];
	stream.getVideoTracks().forEach((t) => t.stop()); // only its sound is wanted
	if (state.capturing !== token) { stream.getTracks().forEach((t) => t.stop()); ctx.close().catch(() => {}); return; }
	state.capturing = null;
	if (!track) {
		ctx.close().catch(() => {});
		setStatus('What was shared has no sound: share a tab, and tick “Share tab audio” in the browser’s dialog.', true);
		return;
	}
	// The tab's own playback is muted only for a tab (a screen's sound keeps playing where it is).
	const echo = kind === 'tab' && surface === 'browser' && track.getSettings().suppressLocalAudioPlayback === true;
	try {
		await ctx.audioWorklet.addModule('/static/capture.js');
	} catch (err) {
		stream.getTracks().forEach((t) => t.stop());
		ctx.close().catch(() => {});
		setStatus(`The page could not start capturing: ${err.message || err}`, true);
		return;
	}
	// Connected on to the speakers (it writes silence there): the browser runs only what leads to them.
	const node = new AudioWorkletNode(ctx, 'dancesynth-capture');
	ctx.createMediaStreamSource(stream).connect(node).connect(ctx.destination);
	const mine = openLive({ source: kind, rate: String(ctx.sampleRate) }, ctx,
		{ kind, stream, node, echo, sent_s: 0 });
	node.port.onmessage = (ev) => {
		if (live !== mine || mine.capture.ended || mine.ws.readyState !== WebSocket.OPEN) return;
		mine.capture.sent_s += ev.data.byteLength / 2 / ctx.sampleRate;
		mine.ws.send(ev.data);
		state.live.capture.sent_s = mine.capture.sent_s;
	};
	track.addEventListener('ended', () => { if (live === mine) endCapture(mine); });
	setStatus(`Sending ${what} to the server…`);
}

// The capture ends (the user stopped sharing, or pressed Stop): the server dances to the end of what it heard.
function endCapture(mine) {
	mine.capture.ended = true;
	mine.capture.stream.getTracks().forEach((t) => t.stop());
	if (mine.ws.readyState === WebSocket.OPEN) mine.ws.send(JSON.stringify({ type: 'end' }));
	setStatus(`Stopped listening to ${CAPTURE_NAMES[mine.capture.kind]}; the dance goes on to the end of what was ` +
		'heard (Stop again ends it now)');
}

function captureRefused(kind, err) {
	const what = CAPTURE_NAMES[kind];
	if (err.name === 'NotAllowedError') {
		return kind === 'tab' ? 'No tab was shared (the browser refused, or the choice was cancelled). Press ' +
			'“Dance to a tab” again and pick a tab, with “Share tab audio” ticked.' :
			'The browser refused the microphone. Allow it for this site (the icon in the address bar) and press ' +
			'“Dance to the microphone” again.';
	}
	if (err.name === 'NotFoundError') return `No ${kind === 'tab' ? 'tab or screen' : 'microphone'} was found to share.`;
	if (err.name === 'NotReadableError') return `${what} could not be opened (is another program using it?).`;
	return `Could not capture ${what}: ${err.name}: ${err.message}`;
}

// One live dance in the page: a stream's (query.url) or a capture's (query.source, query.rate).
function openLive(query, ctx, capture) {
	const character = $('live-character').value;
	const mesh = Boolean(characterInfo[character] && characterInfo[character].mesh);
	const params = new URLSearchParams({ ...query, segment_s: $('live-segment').value || '5', style: $('style').value,
		seed: $('seed').value, character });
	const ws = new WebSocket(`${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/ws/live?${params}`);
	ws.binaryType = 'arraybuffer';
	$('engine').disabled = true; // live is always the streaming engine
	$('live-pause').hidden = false;
	$('live-pause').textContent = 'Pause';
	const out = ctx.createGain();
	out.gain.value = capture && !capture.echo ? 0 : Number($('volume').value);
	out.connect(ctx.destination);
	live = { ws, ctx, out, capture, t0: null, last: null, sr: 22050, samples: 0, fps: 30, delay: 10,
		start: 0, hierarchy: null, rows: [], base: null, beats: [], time: 0, character, stick: null, model: null };
	state.live = { state: 'connecting', frames: 0, beats: 0, time: 0, heard_s: 0, error: null, starved_s: 0, motion_until_s: 0,
		playing_s: 0, server_late_s: 0, delay_s: null, character, model: mesh ? 'loading' : null,
		capture: capture && { kind: capture.kind, rate: ctx.sampleRate, echo: capture.echo, sent_s: 0 } };
	$('info').textContent = mesh ? `Live: the ${character}` : `Live: the stick figure on the ${character} rig`;
	offerFigures(false); // the stick figure until the character's mesh is here
	offerDownloads(null);
	$('edit-panel').hidden = true; // a live dance is not edited
	edits.length = 0;
	span = null;
	const mine = live;
	if (mesh) {
		loadModel(`/api/characters/${encodeURIComponent(character)}.glb`).then((model) => {
			if (live !== mine) return;
			live.model = model;
			state.live.model = 'ready';
			offerFigures(true);
			showLive();
		}).catch((err) => { if (live === mine) liveModelFailed(String(err.message || err)); });
	}
	// How the dance stands against what the user hears: a stream's sound plays here, in step with it; a
	// capture's is heard where it plays, this long before its dance.
	const behind = () => capture && !capture.echo ? `dancing ${live.delay.toFixed(1)} s behind ${CAPTURE_NAMES[capture.kind]}`
		: `playing ${live.delay.toFixed(1)} s behind the ${capture ? 'tab' : 'stream'}`;
	ws.onmessage = (ev) => {
		if (live !== mine) return;
		if (typeof ev.data !== 'string') { liveAudio(ev.data); return; }
		const m = JSON.parse(ev.data);
		if (m.type === 'start') {
			live.sr = m.sr; live.delay = m.delay_s; live.fps = m.fps; live.start = m.start_s || 0;
			state.live.delay_s = m.delay_s;
			state.live.state = 'listening';
			setStatus(`Listening; the dance starts ${m.delay_s.toFixed(1)} s after the music arrives…`);
		} else if (m.type === 'hierarchy') {
			live.hierarchy = m.bvh; live.fps = m.fps;
		} else if (m.type === 'frames') {
			liveFrames(m.start_frame, m.rows);
			state.live.state = 'dancing';
			setStatus(`Live: ${(state.live.frames / live.fps).toFixed(1)} s of dance ready, ` +
				`${state.live.heard_s.toFixed(1)} s heard, ${behind()}`);
		} else if (m.type === 'beats') {
			live.beats.push(...m.beats);
			state.live.beats = live.beats.length;
			state.live.tempo_bpm = m.tempo_bpm;
			state.live.server_late_s += m.late_s || 0;
		} else if (m.type === 'end') {
			state.live.state = 'ended';
			state.live.summary = m.summary;
			setStatus(`The ${capture ? 'capture' : 'stream'} ended: ${m.summary.segments} segments, style ` +
				`${m.summary.style}; the dance plays to the end of the music`);
		} else if (m.type === 'error') {
			state.live.state = 'error';
			state.live.error = m.error;
			setStatus(`Live: ${m.error}`, true);
		}
	};
	ws.onclose = () => {
		if (live === mine && !['ended', 'error'].includes(state.live.state)) {
			state.live.state = 'closed';
			setStatus('The connection to the server closed.', true);
		}
		if (live === mine && capture) capture.stream.getTracks().forEach((t) => t.stop());
	};
	return mine;
}

$('live-controls').addEventListener('submit', startLive);
$('live-tab').addEventListener('click', () => startCapture('tab'));
$('live-mic').addEventListener('click', () => startCapture('mic'));
$('stop-live').addEventListener('click', () => {
	if (live && live.capture && !live.capture.ended && live.ws.readyState === WebSocket.OPEN) { endCapture(live); return; }
	stopLive();
	setStatus('Stopped.');
});
audio.addEventListener('play', () => { if (live) stopLive(); });
$('controls').addEventListener('submit', requestDance);
$('figure').addEventListener('change', () => { wantedFigure = $('figure').value; updateView(); });
$('camera-view').addEventListener('change', chooseView);
// Live, pausing holds the music and the dance where they are (the stream goes on arriving; they resume
// from there, that much further behind it); the volume is the song's and the live stream's alike.
$('live-pause').addEventListener('click', () => {
	if (!live) return;
	const pausing = live.ctx.state === 'running';
	(pausing ? live.ctx.suspend() : live.ctx.resume()).catch(() => {});
	$('live-pause').textContent = pausing ? 'Resume' : 'Pause';
	state.live.paused = pausing;
});
$('volume').addEventListener('input', () => {
	const volume = Number($('volume').value);
	audio.volume = volume;
	if (live && !(live.capture && !live.capture.echo)) live.out.gain.value = volume;
});
$('dl-mp4').addEventListener('click', downloadVideo);
for (const kind of ['bvh', 'glb', 'vrma', 'fbx']) $(`dl-${kind}`).addEventListener('click', downloadFile);
$('engine').addEventListener('change', fitChoices);
$('style').addEventListener('change', fitChoices);
$('file').addEventListener('change', () => { if ($('file').files.length) $('song').value = ''; });
$('character').addEventListener('change', showOwnCharacter);
$('edit-controls').addEventListener('submit', redance);
$('select-bars').addEventListener('click', () => barsFromHere(4));
$('undo').addEventListener('click', undo);
// A song (or a character file) dropped anywhere on the page is danced at once, as if chosen and Dance pressed.
document.addEventListener('dragover', (ev) => {
	if (![...ev.dataTransfer.types].includes('Files')) return;
	ev.preventDefault();
	document.body.classList.add('dropping');
});
document.addEventListener('dragleave', (ev) => { if (!ev.relatedTarget) document.body.classList.remove('dropping'); });
document.addEventListener('drop', (ev) => {
	document.body.classList.remove('dropping');
	if (!ev.dataTransfer.files.length) return;
	ev.preventDefault();
	const file = ev.dataTransfer.files[0];
	if (/\.(glb|gltf|vrm|bvh)$/i.test(file.name)) { // a character: the chosen song danced on it
		$('character-file').files = ev.dataTransfer.files;
		$('character').value = OWN;
		showOwnCharacter();
	} else {
		$('file').files = ev.dataTransfer.files;
		$('song').value = '';
	}
	$('controls').requestSubmit();
});

// The live controls are folded away on a small screen (the stage needs the room), open on a large one.
$('live-panel').open = window.matchMedia('(min-width: 700px)').matches; // the edit panel opens when asked for
const tLoad = performance.now();
loadChoices().then(() => {
	state.timings.choices_ms = performance.now() - tLoad;
	state.state = 'idle';
	setStatus('Pick a song (or a file) and press Dance.');
}).catch((err) => {
	state.state = 'error';
	state.error = String(err.message || err);
	setStatus(`Could not reach the server: ${state.error}`, true);
});
requestAnimationFrame(frame);
