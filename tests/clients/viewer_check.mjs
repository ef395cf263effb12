// Drive the dancesynth page in headless Chromium and take two screenshots of the 3D view
// about 0.5 s apart, once the character dances.
//
// Run by tests/test_serve.py as
//     node tests/clients/viewer_check.mjs URL OUT_DIR song SONG_SUBSTRING [CHROMIUM]
//         pick a bundled song, press Dance, play it;
//     node tests/clients/viewer_check.mjs URL OUT_DIR live STREAM_URL [CHROMIUM]
//         dance live to an http stream (2 s segments), played with the delay the server asks for.
// Writes OUT_DIR/a.png and OUT_DIR/b.png and prints one JSON object on stdout (timings,
// the music clock at each shot, page errors); every wait is bounded.
import { chromium } from 'playwright-core';

const [url, outDir, mode, value, executablePath = '/usr/bin/chromium'] = process.argv.slice(2);
const report = { ok: false, errors: [], console: [], timings: {}, times: [] };
const t0 = Date.now();
const since = () => Date.now() - t0;

let browser;
try {
	browser = await chromium.launch({
		executablePath,
		headless: true,
		timeout: 30000,
		args: ['--no-sandbox', '--disable-gpu', '--enable-unsafe-swiftshader', '--disable-background-networking',
			'--disable-component-update', '--disable-sync', '--autoplay-policy=no-user-gesture-required',
			'--mute-audio'],
	});
	report.timings.browser_ms = since();
	const page = await browser.newPage({ viewport: { width: 800, height: 600 } });
	page.setDefaultTimeout(20000);
	page.on('pageerror', (e) => report.errors.push(`pageerror: ${e.message}`));
	page.on('console', (m) => { if (m.type() === 'error') report.console.push(m.text()); });

	await page.goto(url, { waitUntil: 'load', timeout: 20000 });
	await page.waitForFunction(() => window.dancesynth && window.dancesynth.state !== 'loading', null,
		{ timeout: 30000 });
	report.timings.page_ready_ms = since();
	const loaded = await page.evaluate(() => window.dancesynth.state);
	if (loaded !== 'idle') throw new Error(`page did not load: ${await page.evaluate(() => window.dancesynth.error)}`);

	let clock;
	if (mode === 'live') {
		await page.fill('#live-url', value);
		await page.fill('#live-segment', '2');
		await page.click('#go-live');
		await page.waitForFunction(() => ['error', 'closed'].includes(window.dancesynth.live.state) ||
			(window.dancesynth.live.time > 1.0 && window.dancesynth.live.frames > 45), null, { timeout: 40000 });
		report.timings.live_dancing_ms = since();
		report.page = await page.evaluate(() => ({ ...window.dancesynth, status: document.getElementById('status').textContent }));
		if (report.page.live.error || report.page.live.state === 'closed') throw new Error(`live failed: ${report.page.live.error}`);
		clock = () => window.dancesynth.live.time;
	} else {
		const option = await page.evaluate((part) => {
			const opt = [...document.querySelectorAll('#song option')].find((o) => o.value.includes(part));
			return opt ? opt.value : null;
		}, value);
		if (!option) throw new Error(`no song matching ${value}`);
		await page.selectOption('#song', option);
		const tDance = Date.now();
		await page.click('#dance');
		await page.waitForFunction(() => ['ready', 'error'].includes(window.dancesynth.state), null, { timeout: 90000 });
		report.timings.dance_ms = Date.now() - tDance;
		const st = await page.evaluate(() => ({ ...window.dancesynth, status: document.getElementById('status').textContent }));
		report.page = st;
		if (st.state !== 'ready') throw new Error(`dance failed: ${st.error}`);

		// Play from the start (autoplay is allowed by the flag above) and wait for the clock to run.
		await page.evaluate(() => { const a = document.getElementById('audio'); a.currentTime = 0; return a.play(); });
		await page.waitForFunction(() => document.getElementById('audio').currentTime > 1.0, null, { timeout: 15000 });
		clock = () => document.getElementById('audio').currentTime;
	}
	const view = page.locator('#view');
	for (const name of ['a', 'b']) {
		report.times.push(await page.evaluate(clock));
		await view.screenshot({ path: `${outDir}/${name}.png`, timeout: 10000 });
		if (name === 'a') await page.waitForTimeout(500);
	}
	report.ok = true;
} catch (e) {
	report.errors.push(`exception: ${e && e.stack ? e.stack : e}`);
} finally {
	report.timings.total_ms = since();
	if (browser) await browser.close().catch(() => {});
}
process.stdout.write(JSON.stringify(report));
