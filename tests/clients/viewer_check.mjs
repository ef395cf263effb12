// Drive the dancesynth page in headless Chromium and take two screenshots of the 3D view
// about 0.5 s apart, once the character dances.
//
// Run by tests/test_serve.py as
//     node tests/clients/viewer_check.mjs URL OUT_DIR song SONG_SUBSTRING [CHROMIUM] [OPTIONS]
//         pick a bundled song, press Dance, play it;
//     node tests/clients/viewer_check.mjs URL OUT_DIR live STREAM_URL [CHROMIUM] [OPTIONS]
//         dance live to an http stream (2 s segments), played with the delay the server asks for;
//         the shots wait for the character's mesh (if it has one) as well as for the motion;
//     node tests/clients/viewer_check.mjs URL OUT_DIR capture tab|mic [CHROMIUM] [OPTIONS]
//         press "Dance to a tab" (or "... the microphone"): Chromium's fake capture device plays
//         OPTIONS.audio_file; with OPTIONS.refuse the browser refuses instead, and the report holds
//         the status line (no shots); with OPTIONS.capture_s, once that much has been sent the report
//         presses Stop and waits for the dance's end (the server's summary is in page.live.summary);
//         OPTIONS.segment: the segment length (default 2 s, live too).
// OPTIONS, JSON: {"engine": .., "character": ..} choose them before Dance (live: the character only);
// "stick": true also switches to the stick figure and takes c.png and d.png;
// "playback": true pauses, seeks and plays to the end, noting the status line each time;
// "video": true presses the MP4 button and saves the download as OUT_DIR/dance.mp4;
// "pause": true (live) pauses for a second, resumes for one and sets the volume, noting the music clock.
// Writes OUT_DIR/a.png, OUT_DIR/b.png and OUT_DIR/page.png (the whole page) and prints one JSON
// object on stdout (timings, the music clock and status line at each shot, page errors); every
// wait is bounded.
import { launchChromium } from './headless.mjs';

const [url, outDir, mode, value, executablePath = '/usr/bin/chromium', optionsJSON = '{}'] = process.argv.slice(2);
const options = JSON.parse(optionsJSON);
const report = { ok: false, errors: [], console: [], timings: {}, times: [], statuses: {}, video: {} };
const t0 = Date.now();
const since = () => Date.now() - t0;

let browser;
try {
	const fake = mode !== 'capture' ? [] : options.refuse ? ['--use-fake-device-for-media-stream'] :
		['--use-fake-device-for-media-stream', '--use-fake-ui-for-media-stream',
			`--use-file-for-fake-audio-capture=${options.audio_file}`];
	browser = await launchChromium(executablePath, ['--autoplay-policy=no-user-gesture-required', '--mute-audio', ...fake]);
	report.timings.browser_ms = since();
	// Dark, the page's default theme: the shots are checked against its colours.
	const page = await browser.newPage({ viewport: { width: 1000, height: 700 }, acceptDownloads: true,
		colorScheme: 'dark' });
	page.setDefaultTimeout(20000);
	page.on('pageerror', (e) => report.errors.push(`pageerror: ${e.message}`));
	page.on('console', (m) => { if (m.type() === 'error') report.console.push(m.text()); });
	const pageState = () => page.evaluate(() => ({ ...window.dancesynth, status: document.getElementById('status').textContent }));
	const statusText = () => page.evaluate(() => document.getElementById('status').textContent);
	const view = page.locator('#view');

	await page.goto(url, { waitUntil: 'load', timeout: 20000 });
	await page.waitForFunction(() => window.dancesynth && window.dancesynth.state !== 'loading', null,
		{ timeout: 30000 });
	report.timings.page_ready_ms = since();
	const loaded = await page.evaluate(() => window.dancesynth.state);
	if (loaded !== 'idle') throw new Error(`page did not load: ${await page.evaluate(() => window.dancesynth.error)}`);

	let clock;
	if (mode === 'capture' && options.refuse) {
		await page.click(value === 'tab' ? '#live-tab' : '#live-mic');
		await page.waitForFunction(() => document.getElementById('status').classList.contains('error'), null,
			{ timeout: 10000 });
		report.statuses.refused = await statusText();
		report.page = await pageState();
		report.ok = true;
		throw null; // done: nothing to shoot
	}
	if (mode === 'live' || mode === 'capture') {
		await page.fill('#live-segment', String(options.segment || 2));
		if (options.character) await page.selectOption('#live-character', options.character);
		if (mode === 'live') {
			await page.fill('#live-url', value);
			await page.click('#go-live');
		} else {
			await page.click(value === 'tab' ? '#live-tab' : '#live-mic');
		}
		// A capture has no live dance until the browser has shared the sound (or an error says why not).
		await page.waitForFunction(() => {
			const live = window.dancesynth.live;
			if (!live) return document.getElementById('status').classList.contains('error');
			return ['error', 'closed'].includes(live.state) ||
				(live.time > 1.0 && live.frames > 45 && live.model !== 'loading');
		}, null, { timeout: 40000 });
		report.timings.live_dancing_ms = since();
		report.page = await pageState();
		if (!report.page.live || report.page.live.error || report.page.live.state === 'closed') {
			throw new Error(`live failed: ${report.page.live ? report.page.live.error : report.page.status}`);
		}
		report.view_live = report.page.view;
		clock = () => window.dancesynth.live.time;
	} else {
		const option = await page.evaluate((part) => {
			const opt = [...document.querySelectorAll('#song option')].find((o) => o.value.includes(part));
			return opt ? opt.value : null;
		}, value);
		if (!option) throw new Error(`no song matching ${value}`);
		await page.selectOption('#song', option);
		for (const field of ['engine', 'character']) {
			if (options[field]) await page.selectOption(`#${field}`, options[field]);
		}
		const tDance = Date.now();
		await page.click('#dance');
		await page.waitForFunction(() => ['ready', 'error'].includes(window.dancesynth.state), null, { timeout: 90000 });
		report.timings.dance_ms = Date.now() - tDance;
		const st = await pageState();
		report.page = st;
		if (st.state !== 'ready') throw new Error(`dance failed: ${st.error}`);

		// Play from the start (autoplay is allowed by the flag above) and wait for the clock to run.
		await playFrom(page, 0, 1.0);
		clock = () => document.getElementById('audio').currentTime;
	}
	// Two shots 0.5 s apart, with the music clock and the status line at each.
	const shots = async (names) => {
		for (const name of names) {
			// Live on a busy machine the motion may come late (the page holds the last pose meanwhile):
			// each shot waits for the motion of the moment it shows.
			if (mode !== 'song') {
				await page.waitForFunction(() => {
					const live = window.dancesynth.live;
					return live.time + 0.1 < live.motion_until_s;
				}, null, { timeout: 30000 });
			}
			report.times.push(await page.evaluate(clock));
			report.statuses[name] = await statusText();
			await view.screenshot({ path: `${outDir}/${name}.png`, timeout: 10000 });
			if (name !== names[names.length - 1]) await page.waitForTimeout(500);
		}
	};
	await shots(['a', 'b']);
	await page.screenshot({ path: `${outDir}/page.png`, timeout: 10000 });
	if (options.stick) {
		await page.selectOption('#figure', 'stick');
		report.view_after_toggle = await page.evaluate(() => window.dancesynth.view);
		if (mode === 'song') await playFrom(page, 0.5, 1.0); // the song may have ended meanwhile
		await shots(['c', 'd']);
	}
	if (options.pause) {   // live: Pause holds the music clock and the dance; Resume goes on from there
		await page.click('#live-pause');
		await page.waitForTimeout(300);
		const held = await page.evaluate(() => window.dancesynth.live.time);
		await page.waitForTimeout(1000);
		report.pause = { held_for_1s: await page.evaluate(() => window.dancesynth.live.time) - held,
			label: await page.evaluate(() => document.getElementById('live-pause').textContent) };
		await page.click('#live-pause');
		await page.waitForTimeout(1000);
		report.pause.resumed_1s = await page.evaluate(() => window.dancesynth.live.time) - held;
		await page.fill('#volume', '0.3');
		report.pause.volume = await page.evaluate(() => document.getElementById('audio').volume);
	}
	if (options.capture_s) {
		await page.waitForFunction((s) => window.dancesynth.live.capture.sent_s >= s, options.capture_s,
			{ timeout: 1000 * options.capture_s + 30000 });
		await page.click('#stop-live');
		report.statuses.stopped = await statusText();
		await page.waitForFunction(() => ['ended', 'error', 'closed'].includes(window.dancesynth.live.state), null,
			{ timeout: 30000 });
		report.timings.ended_ms = since();
		report.statuses.ended = await statusText();
	}
	if (options.playback) await checkPlayback(page, statusText);
	if (options.video) await checkVideo(page);
	report.page = await pageState();
	report.ok = true;
} catch (e) {
	if (e !== null) report.errors.push(`exception: ${e && e.stack ? e.stack : e}`);
} finally {
	report.timings.total_ms = since();
	if (browser) await browser.close().catch(() => {});
}
process.stdout.write(JSON.stringify(report));

// Play the song from `from` s and wait until its clock passes `past` s.
async function playFrom(page, from, past) {
	await page.evaluate((t) => { const a = document.getElementById('audio'); a.currentTime = t; return a.play(); }, from);
	await page.waitForFunction((t) => document.getElementById('audio').currentTime > t, past, { timeout: 15000 });
}

// Pause, seek while paused, then play to the end: the status line should say so each time.
async function checkPlayback(page, statusText) {
	const audio = (fn, arg) => page.evaluate(fn, arg);
	await playFrom(page, 0.5, 1.0);
	await audio(() => document.getElementById('audio').pause());
	await page.waitForFunction(() => window.dancesynth.playback.state === 'paused', null, { timeout: 5000 });
	report.statuses.paused = await statusText();
	await page.waitForTimeout(400);
	report.statuses.paused_later = await statusText(); // the same: the clock stopped
	await audio(() => { document.getElementById('audio').currentTime = 2.0; });
	await page.waitForFunction(() => Math.abs(window.dancesynth.playback.time - 2.0) < 0.05, null, { timeout: 5000 });
	report.statuses.seeked = await statusText();
	await audio(() => {
		const a = document.getElementById('audio');
		a.currentTime = Math.max(a.duration - 0.6, 0);
		return a.play();
	});
	await page.waitForFunction(() => window.dancesynth.playback.state === 'finished', null, { timeout: 10000 });
	report.statuses.finished = await statusText();
	report.playback_end = await page.evaluate(() => window.dancesynth.playback);
}

// Press MP4 and wait for the download, noting the button's states on the way (it renders on the server).
async function checkVideo(page) {
	const seen = new Set();
	const t = Date.now();
	const download = page.waitForEvent('download', { timeout: 120000 });
	await page.click('#dl-mp4');
	const poll = setInterval(() => {
		page.evaluate(() => document.getElementById('dl-mp4').textContent).then((s) => seen.add(s)).catch(() => {});
	}, 100);
	try {
		const file = await download;
		await file.saveAs(`${outDir}/dance.mp4`);
		report.video.file_name = file.suggestedFilename();
	} finally {
		clearInterval(poll);
	}
	report.video.ms = Date.now() - t;
	report.video.labels = [...seen];
	report.video.state = await page.evaluate(() => window.dancesynth.video);
}
