// The page's dance-studio behaviours in headless Chromium, one scenario a run:
//     node tests/clients/studio_check.mjs URL OUT_DIR SCENARIO [CHROMIUM]
// stale-video: MP4 of a long song, then dance a short one and ask for its MP4: which file is saved, and
//              what became of the first render;
// neural-styles: the style and engine menus with the neural engine and with a style it has not learned;
// gone: dance, let the server forget it (two more dances through the API), then press BVH and MP4;
// error-keeps-label: dance, then ask for one that fails: what the info line says;
// small-things: the limits shown before an upload, a file dropped on the page, one too large, the engine
//         menu during live, the controls' accessible names;
// framing: at 390x844 and 1280x800, 10 moments of Vibe Ace as it plays and 10 right after seeks: the
//         dancer's box on the stage (window.dancesynthFrame) at each (framing-*.png: the last one);
// timeline: click the timeline at its middle, then J/K/L, the arrows and Shift+arrows, space: the time and
//         the status line after each;
// axe: axe-core's serious and critical violations with the page idle, dancing, live and after an error;
// own-character: choose "your own file" and a GLB (the mannequin's, as "My Avatar.glb"), dance, download
//         its GLB and VRMA (own-*.glb, own-*.vrma); then OUT_DIR/evil.gltf (a model reaching outside its
//         folder): the message; then OUT_DIR/avatar.vrm dropped on the page: what dances;
// edit: dance Vibe Ace, Shift+drag a span on the timeline, then "4 bars from here" at 20 s and re-dance it
//         with seed 5: the new dance, where its frames differ from the old one's, Undo; a motif that does
//         not exist: the message; the [ and ] keys;
// layout: at 390x844 (a phone) and 1280x800, before and after a dance: the page's width against the
//         window's, and where the stage is (layout-390x844.png, ...).
// Prints one JSON report; every wait is bounded.
import AxeBuilder from '@axe-core/playwright';
import { launchChromium } from './headless.mjs';

const [url, outDir, scenario, executablePath = '/usr/bin/chromium'] = process.argv.slice(2);
const report = { ok: false, errors: [], console: [], scenario };
let browser;
try {
	browser = await launchChromium(executablePath, ['--autoplay-policy=no-user-gesture-required', '--mute-audio']);
	// A context of its own: axe-core's runner needs one.
	const context = await browser.newContext({ viewport: { width: 1280, height: 800 }, acceptDownloads: true,
		colorScheme: 'dark' });
	const page = await context.newPage();
	page.setDefaultTimeout(20000);
	page.on('pageerror', (e) => report.errors.push(`pageerror: ${e.message}`));
	page.on('console', (m) => { if (m.type() === 'error' && !/404|400/.test(m.text())) report.console.push(m.text()); });
	const statusText = () => page.evaluate(() => document.getElementById('status').textContent);
	await page.goto(url, { waitUntil: 'load' });
	await page.waitForFunction(() => window.dancesynth && window.dancesynth.state === 'idle', null, { timeout: 30000 });
	const songValue = (part) => page.evaluate((p) => [...document.querySelectorAll('#song option')]
		.find((o) => o.value.includes(p)).value, part);
	const danceSong = async (part) => {
		await page.selectOption('#song', await songValue(part));
		const before = await page.evaluate(() => window.dancesynth.dance && window.dancesynth.dance.id);
		await page.click('#dance');
		await page.waitForFunction((b) => ['ready', 'error'].includes(window.dancesynth.state) &&
			(window.dancesynth.state === 'error' || (window.dancesynth.dance && window.dancesynth.dance.id !== b)),
		before, { timeout: 90000 });
		return page.evaluate(() => ({ ...window.dancesynth.dance, state: window.dancesynth.state }));
	};

	if (scenario === 'stale-video') {
		const first = await danceSong('Vibe_Ace');
		await page.click('#dl-mp4');
		await page.waitForFunction(() => window.dancesynth.video && ['queued', 'rendering']
			.includes(window.dancesynth.video.state), null, { timeout: 30000 });
		const second = await danceSong('trumpet');
		const download = page.waitForEvent('download', { timeout: 120000 });
		await page.click('#dl-mp4');
		const file = await download;
		report.first_id = first.id;
		report.second_id = second.id;
		report.saved = file.suggestedFilename();
		report.first_render = await page.evaluate((id) => fetch(`/api/dances/${id}/video?figure=character`)
			.then((r) => r.json()), first.id);
		report.video = await page.evaluate(() => window.dancesynth.video);
	} else if (scenario === 'neural-styles') {
		const menus = () => page.evaluate(() => ({
			styles: [...document.querySelectorAll('#style option')].map((o) => ({ value: o.value, disabled: o.disabled })),
			engines: [...document.querySelectorAll('#engine option')].map((o) => ({ value: o.value, disabled: o.disabled })),
			style: document.getElementById('style').value }));
		report.at_start = await menus();
		await page.selectOption('#engine', 'neural');
		report.with_neural = await menus();
		await page.selectOption('#engine', 'streaming');
		const other = report.at_start.styles.find((s) => s.value && !s.value.startsWith('salsa'));
		await page.selectOption('#style', other.value);
		report.with_other_style = await menus();
		report.api = await page.evaluate((style) => {
			const form = new FormData();
			for (const [k, v] of Object.entries({ song: document.getElementById('song').value, engine: 'neural', style })) {
				form.append(k, v);
			}
			return fetch('/api/dance', { method: 'POST', body: form }).then(async (r) => ({ status: r.status, body: await r.json() }));
		}, other.value);
	} else if (scenario === 'gone') {
		await danceSong('trumpet');
		await page.evaluate(async () => { // two more dances than the server keeps: the one on stage is let go
			for (let i = 0; i < 2; i++) {
				const form = new FormData();
				form.append('song', document.getElementById('song').value);
				form.append('seed', String(i + 1));
				await fetch('/api/dance', { method: 'POST', body: form });
			}
		});
		let saved = null;
		page.on('download', (d) => { saved = d.suggestedFilename(); });
		await page.click('#dl-bvh');
		await page.waitForFunction(() => document.getElementById('notice').classList.contains('error'), null,
			{ timeout: 10000 });
		report.after_bvh = await page.evaluate(() => document.getElementById('notice').textContent);
		report.links = await page.evaluate(() => ['bvh', 'glb', 'vrma', 'fbx'].map((k) =>
			document.getElementById(`dl-${k}`).getAttribute('aria-disabled')));
		report.mp4_disabled = await page.evaluate(() => document.getElementById('dl-mp4').disabled);
		await page.waitForTimeout(500);
		report.saved = saved;
	} else if (scenario === 'error-keeps-label') {
		await danceSong('trumpet');
		report.info_before = await page.evaluate(() => document.getElementById('info').textContent);
		await page.fill('#seed', '-5');
		await page.click('#dance');
		await page.waitForFunction(() => window.dancesynth.state === 'error', null, { timeout: 30000 });
		report.status = await statusText();
		report.info_after = await page.evaluate(() => document.getElementById('info').textContent);
	} else if (scenario === 'small-things') {
		report.limits = await page.evaluate(() => document.getElementById('limits').textContent);
		const drop = (size, name) => page.evaluate(async ([size, name]) => {
			const bytes = size ? new Uint8Array(size) : await (await fetch(`/api/songs/${encodeURIComponent(
				[...document.querySelectorAll('#song option')].find((o) => o.value.includes('trumpet')).value)}`)).arrayBuffer();
			const dt = new DataTransfer();
			dt.items.add(new File([bytes], name, { type: 'audio/ogg' }));
			document.dispatchEvent(new DragEvent('drop', { dataTransfer: dt, bubbles: true, cancelable: true }));
		}, [size, name]);
		let uploads = 0;
		page.on('request', (r) => { if (r.url().endsWith('/api/dance')) uploads += 1; });
		await drop(51 * 2 ** 20, 'huge.ogg');
		await page.waitForTimeout(300);
		report.too_large = { status: await statusText(), uploads };
		await drop(0, 'my song.ogg');
		await page.waitForFunction(() => ['ready', 'error'].includes(window.dancesynth.state) && window.dancesynth.dance,
			null, { timeout: 60000 });
		report.dropped = await page.evaluate(() => ({ state: window.dancesynth.state, song: document.getElementById('song').value,
			file: document.getElementById('file').files[0] && document.getElementById('file').files[0].name,
			audio: document.getElementById('audio').src }));
		await page.fill('#live-url', 'http://127.0.0.1:9/nothing.ogg');
		await page.click('#go-live');
		report.engine_disabled_live = await page.evaluate(() => document.getElementById('engine').disabled);
		await page.click('#stop-live');
		report.engine_disabled_after = await page.evaluate(() => document.getElementById('engine').disabled);
		report.names = await page.evaluate(() => [...document.querySelectorAll('select, input, button, a[id^="dl-"]')]
			.map((e) => (e.getAttribute('aria-label') || (e.closest('label') && e.closest('label').textContent) ||
				e.textContent || '').trim().replace(/\s+/g, ' ')));
	} else if (scenario === 'framing') {
		report.sizes = {};
		for (const [width, height] of [[390, 844], [1280, 800]]) {
			await page.setViewportSize({ width, height });
			await page.reload({ waitUntil: 'load' });
			await page.waitForFunction(() => window.dancesynth && window.dancesynth.state === 'idle', null,
				{ timeout: 30000 });
			await danceSong('Vibe_Ace');
			const boxes = [];
			const nextFrames = () => page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
			await page.evaluate(() => { const a = document.getElementById('audio'); a.currentTime = 20; return a.play(); });
			for (let i = 0; i < 10; i++) {
				await page.waitForTimeout(300);
				boxes.push({ kind: 'playing', t: await page.evaluate(() => document.getElementById('audio').currentTime),
					...await page.evaluate(() => window.dancesynthFrame()) });
			}
			for (const t of [55, 3, 40, 12, 30, 58, 8, 47, 25, 35]) {
				await page.evaluate((s) => { document.getElementById('audio').currentTime = s; }, t);
				await page.waitForFunction((s) => Math.abs(document.getElementById('audio').currentTime - s) < 0.5, t);
				await nextFrames();
				boxes.push({ kind: 'seek', t, ...await page.evaluate(() => window.dancesynthFrame()) });
			}
			report.sizes[`${width}x${height}`] = boxes;
			await page.screenshot({ path: `${outDir}/framing-${width}x${height}.png` });
		}
		// The follow view (the default): the camera turns with the yaw the server sent (the MP4's).
		report.default_view = await page.evaluate(() => document.getElementById('camera-view').value);
		await page.selectOption('#camera-view', 'three-quarter');
		await page.selectOption('#camera-view', 'follow');
		report.camera = await page.evaluate(() => window.dancesynth.dance.camera);
		report.follow = [];
		for (const t of [5, 18, 33, 47, 59]) {
			await page.evaluate((s) => { document.getElementById('audio').currentTime = s; }, t);
			await page.waitForFunction((s) => Math.abs(document.getElementById('audio').currentTime - s) < 0.5, t);
			await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
			report.follow.push({ t: await page.evaluate(() => document.getElementById('audio').currentTime),
				...await page.evaluate(() => window.dancesynthFrame()) });
		}
		await page.screenshot({ path: `${outDir}/framing-follow.png` });
	} else if (scenario === 'timeline') {
		await danceSong('Vibe_Ace');
		await page.evaluate(() => { const a = document.getElementById('audio'); a.pause(); a.currentTime = 0; });
		const now = () => page.evaluate(() => ({ t: document.getElementById('audio').currentTime,
			paused: document.getElementById('audio').paused, status: document.getElementById('status').textContent }));
		const settle = () => page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(r))));
		report.marks = await page.evaluate(() => ({ beats: window.dancesynth.dance.beats,
			downbeats: window.dancesynth.dance.downbeats, timeline: window.dancesynth.timeline }));
		const box = await page.locator('#timeline').boundingBox();
		await page.mouse.click(box.x + box.width / 2, box.y + box.height / 2);
		await settle();
		report.steps = [{ action: 'click middle', ...await now() }];
		for (const key of ['l', 'j', 'ArrowRight', 'ArrowRight', 'ArrowLeft', 'Shift+ArrowRight', ' ', ' ']) {
			await page.keyboard.press(key);
			await settle();
			report.steps.push({ action: key, ...await now() });
		}
		report.duration = await page.evaluate(() => document.getElementById('audio').duration);
		await page.evaluate(() => document.getElementById('audio').pause());
	} else if (scenario === 'axe') {
		const audit = async () => (await new AxeBuilder({ page }).analyze()).violations
			.filter((v) => ['serious', 'critical'].includes(v.impact))
			.map((v) => ({ id: v.id, impact: v.impact, help: v.help, nodes: v.nodes.slice(0, 3).map((n) => n.target.join(' ')) }));
		report.states = { idle: await audit() };
		await danceSong('trumpet');
		report.states.dancing = await audit();
		await page.click('#edit-panel summary');
		await page.click('#select-bars');
		report.states.editing = await audit();
		await page.fill('#live-url', 'http://127.0.0.1:9/nothing.ogg');
		await page.click('#go-live');
		report.states.live = await audit();
		await page.click('#stop-live');
		await page.fill('#seed', '-5');
		await page.click('#dance');
		await page.waitForFunction(() => window.dancesynth.state === 'error', null, { timeout: 30000 });
		report.states.error = await audit();
		await page.emulateMedia({ colorScheme: 'light' });   // the light theme, as a system set to light asks
		await page.fill('#seed', '');
		await danceSong('Vibe_Ace');
		report.states.light_dancing = await audit();
		report.light_background = await page.evaluate(() => getComputedStyle(document.body).backgroundColor);
		await page.screenshot({ path: `${outDir}/light.png` });
	} else if (scenario === 'own-character') {
		const { readFile } = await import('node:fs/promises');
		const whenDanced = async (before) => {
			await page.waitForFunction((b) => window.dancesynth.state === 'error' || (window.dancesynth.state === 'ready' &&
				window.dancesynth.dance && window.dancesynth.dance.id !== b), before, { timeout: 90000 });
			return page.evaluate(() => ({ state: window.dancesynth.state, id: window.dancesynth.dance && window.dancesynth.dance.id,
				character: window.dancesynth.dance && window.dancesynth.dance.character, view: window.dancesynth.view,
				status: document.getElementById('status').textContent, info: document.getElementById('info').textContent }));
		};
		await page.selectOption('#song', await songValue('trumpet'));
		report.hidden_before = await page.isHidden('#own-character');
		await page.selectOption('#character', ':own');
		report.hidden_after = await page.isHidden('#own-character');
		await page.click('#dance');   // no file chosen yet: a message, nothing sent
		report.no_file = await statusText();
		const glb = await (await page.request.get(new URL('api/characters/mannequin.glb', url).href)).body();
		await page.setInputFiles('#character-file', { name: 'My Avatar.glb', mimeType: 'model/gltf-binary', buffer: glb });
		await page.click('#dance');
		report.own = await whenDanced(null);
		for (const kind of ['glb', 'vrma', 'fbx']) {
			const download = page.waitForEvent('download', { timeout: 120000 });
			await page.click(`#dl-${kind}`);
			const file = await download;
			report[`saved_${kind}`] = file.suggestedFilename();
			await file.saveAs(`${outDir}/own-${kind}.${kind}`);
		}
		await page.screenshot({ path: `${outDir}/own-character.png` });
		await page.setInputFiles('#character-file', { name: 'evil.gltf', mimeType: 'model/gltf+json',
			buffer: await readFile(`${outDir}/evil.gltf`) });
		await page.click('#dance');
		report.evil = await whenDanced(report.own.id);
		await page.evaluate(async (bytes) => {   // a VRM avatar dropped on the page
			const dt = new DataTransfer();
			dt.items.add(new File([new Uint8Array(bytes)], 'avatar.vrm'));
			document.dispatchEvent(new DragEvent('drop', { dataTransfer: dt, bubbles: true, cancelable: true }));
		}, [...await readFile(`${outDir}/avatar.vrm`)]);
		report.dropped = await whenDanced(report.own.id);
	} else if (scenario === 'edit') {
		const before = await danceSong('Vibe_Ace');
		const info = () => page.evaluate(() => document.getElementById('info').textContent);
		report.info_before = await info();
		await page.evaluate(() => { const a = document.getElementById('audio'); a.pause(); a.currentTime = 0; });
		report.panel_folded = !(await page.isVisible('#edit-controls')) && await page.isVisible('#edit-panel summary');
		const box = await page.locator('#timeline').boundingBox();
		await page.keyboard.down('Shift');
		await page.mouse.move(box.x + box.width * 0.3, box.y + box.height / 2);
		await page.mouse.down();
		await page.mouse.move(box.x + box.width * 0.4, box.y + box.height / 2, { steps: 4 });
		await page.mouse.up();
		await page.keyboard.up('Shift');
		report.dragged = await page.evaluate(() => ({ ...window.dancesynth.edit, open: document.getElementById('edit-panel').open,
			time: document.getElementById('audio').currentTime, text: document.getElementById('span').textContent }));
		await page.evaluate(() => { document.getElementById('audio').currentTime = 20; });
		await page.waitForFunction(() => Math.abs(document.getElementById('audio').currentTime - 20) < 0.5);
		await page.click('#select-bars');
		report.selected = await page.evaluate(() => window.dancesynth.edit.span);
		await page.fill('#edit-seed', '5');
		await page.click('#redance');
		await page.waitForFunction((b) => ['ready', 'error'].includes(window.dancesynth.state) &&
			window.dancesynth.dance.id !== b, before.id, { timeout: 60000 });
		report.after = await page.evaluate(() => ({ state: window.dancesynth.state, id: window.dancesynth.dance.id,
			edits: window.dancesynth.dance.edits, ms: window.dancesynth.timings.redance_ms,
			time: document.getElementById('audio').currentTime, src: document.getElementById('audio').src,
			undo: !document.getElementById('undo').disabled, status: document.getElementById('status').textContent }));
		report.info_after = await info();
		report.changed = await page.evaluate(async ([a, b]) => {   // where the two dances' BVH frames differ
			const rows = async (id) => (await (await fetch(`/api/dances/${id}/dance.bvh`)).text()).split('MOTION')[1]
				.trim().split('\n').slice(3).map((l) => l.trim().split(/\s+/).map(Number));
			const [x, y] = [await rows(a), await rows(b)];
			const differs = x.map((r, i) => r.some((v, j) => { const d = Math.abs(v - y[i][j]) % 360; return Math.min(d, 360 - d) > 1e-3; }));
			return { frames: x.length, same_length: x.length === y.length, first: differs.indexOf(true),
				last: differs.lastIndexOf(true), count: differs.filter(Boolean).length };
		}, [before.id, report.after.id]);
		await page.screenshot({ path: `${outDir}/edit.png` });
		await page.click('#undo');
		report.undone = await page.evaluate(() => ({ id: window.dancesynth.dance.id, state: window.dancesynth.state,
			undo: !document.getElementById('undo').disabled }));
		report.info_undone = await info();
		await page.fill('#edit-seed', '');
		await page.fill('#edit-motif', 'M9999');
		await page.click('#redance');
		await page.waitForFunction(() => window.dancesynth.state === 'error', null, { timeout: 30000 });
		report.bad_motif = { status: await statusText(), id: await page.evaluate(() => window.dancesynth.dance.id) };
		const at = async (t) => {
			await page.evaluate((s) => { const a = document.getElementById('audio'); a.pause(); a.currentTime = s; }, t);
			await page.waitForFunction((s) => Math.abs(document.getElementById('audio').currentTime - s) < 0.05, t);
		};
		await page.focus('#timeline');
		await at(30);
		await page.keyboard.press('[');
		report.bracket_open = await page.evaluate(() => window.dancesynth.edit.span);
		await at(40);
		await page.keyboard.press(']');
		report.bracket_close = await page.evaluate(() => window.dancesynth.edit.span);
	} else if (scenario === 'layout') {
		report.sizes = {};
		for (const [width, height] of [[390, 844], [1280, 800]]) {
			await page.setViewportSize({ width, height });
			await page.reload({ waitUntil: 'load' });   // as a phone opens it
			await page.waitForFunction(() => window.dancesynth && window.dancesynth.state === 'idle', null,
				{ timeout: 30000 });
			const measure = () => page.evaluate(() => ({
				scroll_width: document.documentElement.scrollWidth, window_width: window.innerWidth,
				stage: document.getElementById('stage').getBoundingClientRect().toJSON(),
				live_open: document.getElementById('live-panel').open }));
			const idle = await measure();
			await danceSong('trumpet');
			report.sizes[`${width}x${height}`] = { idle, dancing: await measure() };
			await page.screenshot({ path: `${outDir}/layout-${width}x${height}.png` });
		}
	} else {
		throw new Error(`unknown scenario ${scenario}`);
	}
	await page.screenshot({ path: `${outDir}/page.png` });
	report.ok = true;
} catch (e) {
	report.errors.push(`exception: ${e && e.stack ? e.stack : e}`);
} finally {
	if (browser) await browser.close().catch(() => {});
}
process.stdout.write(JSON.stringify(report));
