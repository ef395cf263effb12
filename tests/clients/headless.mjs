// Headless Chromium as every browser check here starts it (software WebGL, nothing reaching out).
import { chromium } from 'playwright-core';

export const CHROMIUM_ARGS = ['--no-sandbox', '--disable-gpu', '--enable-unsafe-swiftshader',
	'--disable-background-networking', '--disable-component-update', '--disable-sync'];

export function launchChromium(executablePath = '/usr/bin/chromium', extraArgs = []) {
	return chromium.launch({ executablePath, headless: true, timeout: 30000, args: [...CHROMIUM_ARGS, ...extraArgs] });
}
