// "Play as audio": the picture as XY audio through the computer's sound
// card, left = X, right = Y (and the beam on a third output if the device
// has one: blanked +1, lit -1), for an oscilloscope in XY mode on a
// DC-coupled sound card. The worker schedules the shown frame for the
// AudioContext's rate as `isoscope-sim wav --audio-rate RATE` does
// (samples spaced evenly along the path, far enough apart to refresh
// 25 times a second); this file loops it in an AudioBufferSourceNode and
// swaps in the next frame when the picture changes. Every frame starts
// and ends blanked at the park position, so the swap waits for the old
// frame's loop to come round to its start: no jump, no click.
//
// Hooks: setupAudio(call, api) wires the controls (#audio-on,
// #audio-volume, #audio-status) and returns { update }, which app.js calls
// after each new picture; api.audio is for tests (see docs/web.md).

// Seconds ahead of the audio clock a swap is scheduled, so that it is
// not in the past by the time the audio thread sees it.
const LEAD_S = 0.02;

export function setupAudio(call, api) {
  const $ = (id) => document.getElementById(id);
  const on = $('audio-on');
  const volume = $('audio-volume');
  const status = $('audio-status');
  let ctx = null;
  let gain = null;
  // The loop playing: its node, its buffer's duration and when it started.
  let playing = null;
  let wanted = false;
  let busy = false;
  let again = false;

  const state = {
    // The AudioBuffer last handed to WebAudio, its spacing in LSB, and how
    // many have been.
    buffer: null,
    step: null,
    frames: 0,
    rate: () => (ctx ? ctx.sampleRate : null),
    playing: () => wanted,
    // The buffer's first two channels as 16-bit PCM, interleaved (what
    // `wav` writes, round(v * 32767)), base64: for comparing with its file.
    pcm: () => {
      const b = state.buffer;
      if (!b) return null;
      const x = b.getChannelData(0);
      const y = b.getChannelData(1);
      const pcm = new Int16Array(2 * b.length);
      for (let i = 0; i < b.length; i++) {
        pcm[2 * i] = Math.round(x[i] * 32767);
        pcm[2 * i + 1] = Math.round(y[i] * 32767);
      }
      const bytes = new Uint8Array(pcm.buffer);
      let s = '';
      for (let i = 0; i < bytes.length; i += 0x8000) s += String.fromCharCode.apply(null, bytes.subarray(i, i + 0x8000));
      return btoa(s);
    },
  };
  api.audio = state;

  function play(data, step) {
    const rate = ctx.sampleRate;
    const n = data.length / 3;
    const channels = ctx.destination.channelCount >= 3 ? 3 : 2;
    const buffer = ctx.createBuffer(channels, n, rate);
    for (let c = 0; c < channels; c++) buffer.copyToChannel(data.subarray(c * n, (c + 1) * n), c);
    const node = ctx.createBufferSource();
    node.buffer = buffer;
    node.loop = true;
    node.connect(gain);
    // At the old loop's next start (or now).
    let at = ctx.currentTime + LEAD_S;
    if (playing) {
      const { duration, start } = playing;
      at = start + Math.ceil((at - start) / duration) * duration;
      playing.node.stop(at);
    }
    node.start(at);
    playing = { node, duration: n / rate, start: at };
    state.buffer = buffer;
    state.step = step;
    state.frames += 1;
    status.textContent = `${n.toLocaleString('en')} samples a frame, ${step.toFixed(1)} LSB apart: ` +
      `${(rate / n).toFixed(1)} frames/s at ${rate.toLocaleString('en')} Hz, ${channels} channels`;
  }

  // Schedule the shown frame for the sound card; one request at a time,
  // the last change coming after it.
  async function update() {
    if (!wanted) return;
    if (busy) {
      again = true;
      return;
    }
    busy = true;
    try {
      do {
        again = false;
        const { channels, step } = await call('audio', { rate: ctx.sampleRate });
        if (wanted) play(channels, step);
      } while (again && wanted);
    } catch (e) {
      status.textContent = `no audio: ${e && e.message !== undefined ? e.message : e}`;
    } finally {
      busy = false;
    }
  }

  function start() {
    if (!ctx) {
      ctx = new AudioContext();
      const out = ctx.destination;
      out.channelCount = out.maxChannelCount >= 3 ? 3 : 2;
      out.channelCountMode = 'explicit';
      out.channelInterpretation = 'discrete';
      gain = ctx.createGain();
      gain.connect(out);
    }
    gain.gain.value = Number(volume.value);
    wanted = true;
    // Not awaited: a page without a user's gesture may stay suspended.
    ctx.resume();
    return update();
  }

  function stop() {
    wanted = false;
    if (playing) playing.node.stop();
    playing = null;
    status.textContent = '';
    if (ctx) ctx.suspend();
  }

  on.addEventListener('change', () => {
    if (!on.checked) return stop();
    try {
      return start();
    } catch (e) {
      // No AudioContext here (no audio device, or no WebAudio).
      wanted = false;
      status.textContent = `no audio: ${e && e.message !== undefined ? e.message : e}`;
    }
  });
  volume.addEventListener('input', () => {
    if (gain) gain.gain.value = Number(volume.value);
  });
  return { update };
}
