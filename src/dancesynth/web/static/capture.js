// The page's capture (a tab's sound or the microphone) as 16-bit mono PCM at the audio context's rate,
// handed to the page in pieces of 0.1 s to send to the server (an AudioWorklet: the audio thread, so the
// page's own work never drops a sample).
class DancesynthCapture extends AudioWorkletProcessor {
	constructor() {
		super();
		this.size = Math.round(sampleRate * 0.1);
		this.piece = new Int16Array(this.size);
		this.n = 0;
	}

	process(inputs) {
		const channels = inputs[0];
		if (!channels || !channels.length) return true;
		for (let i = 0; i < channels[0].length; i++) {
			let sum = 0;
			for (const channel of channels) sum += channel[i];
			const x = Math.max(-1, Math.min(1, sum / channels.length));
			this.piece[this.n++] = Math.round(x * 32767);
			if (this.n === this.size) {
				this.port.postMessage(this.piece.buffer, [this.piece.buffer]); // handed over: a new one next
				this.piece = new Int16Array(this.size);
				this.n = 0;
			}
		}
		return true;
	}
}

registerProcessor('dancesynth-capture', DancesynthCapture);
