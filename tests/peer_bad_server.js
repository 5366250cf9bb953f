// A misbehaving fxcache server for fxcache-viewer (tests/test_viewer_cli.c, test_misbehaving_server), not
// written with our code: Node's `ws` and the wire format written out by hand from docs/PROTOCOL.md.
//
//   node tests/peer_bad_server.js MODE
//
// Listens on 127.0.0.1 (a free port, printed as "listening on ws://127.0.0.1:PORT"), answers the first hello
// the way MODE says, and exits when the viewer closes. Modes: empty (an empty binary message), text (a text
// message), wrong_type (an unknown type), len_more / len_less (a welcome whose header declares more or fewer
// bytes than it has), frame_first (a frame before the welcome), welcome_twice, nan_camera (frames for a camera
// of NaNs), stall (a welcome, one frame, then nothing), unasked (frames with binary16 depth as asked, and with
// each a samples message for a request never made, for pixels never asked), slow_clock (a frame for the first
// camera only, and an error at a second camera: the viewer runs at --fps 1e-300), tiny_fps (the same with a
// welcome of 1e-30 fps, and an error at a second sample request too), bad_payload (frames whose raw colour
// payload is 3 bytes short: the messages decode, the pictures do not).
'use strict';

const { load_ws, TYPE, header, text8, pose } = require('./peer_wire.js');
const WebSocket = load_ws('peer_bad_server');
const mode = process.argv[2];
setTimeout(() => process.exit(0), 120000).unref();

function u32(v) { const b = Buffer.alloc(4); b.writeUInt32LE(v >>> 0, 0); return b; }
function f32(v) { const b = Buffer.alloc(4); b.writeFloatLE(v, 0); return b; }
function u64(v) { const b = Buffer.alloc(8); b.writeBigUInt64LE(BigInt(v), 0); return b; }

// The welcome: viewer 1, "bad_00", 30 fps, the default scene's room, a camera at (0, 1.6, 3) looking -z.
function welcome(fps) {
    const bounds = Buffer.alloc(48);
    [-5, 0, -4, 5, 4, 4].forEach((v, k) => bounds.writeDoubleLE(v, 8 * k));
    return header(TYPE.welcome, Buffer.concat([u32(1), text8('bad_00'), f32(fps || 30), bounds, pose([0, 1.6, 3], [0, 0, -1], 60), u32(240)]));
}

// An error message (FXC_ERR_RANGE, -10) with a reason.
function error(reason) {
    const r = Buffer.from(reason, 'latin1'), length = Buffer.alloc(2);
    length.writeUInt16LE(r.length, 0);
    return header(TYPE.error, Buffer.concat([Buffer.from([0xf6, 0xff, 0xff, 0xff]), length, r]));
}

// One zstd frame (RFC 8878) holding b in raw blocks: a single segment with a 4-byte content size.
function zstd_raw(b) {
    const parts = [Buffer.from([0x28, 0xb5, 0x2f, 0xfd, 0xa0]), u32(b.length)];
    let at = 0;
    do {
        const n = Math.min(1 << 17, b.length - at), last = at + n >= b.length ? 1 : 0, block = last | (n << 3);
        parts.push(Buffer.from([block & 255, (block >> 8) & 255, (block >> 16) & 255]), b.subarray(at, at + n));
        at += n;
    } while (at < b.length);
    return Buffer.concat(parts);
}

// A raw-colour frame, w x h grey, for camera sequence seq; with `depth`, binary16 depth of 4 m everywhere.
let frame_number = 0;
function frame(w, h, seq, position, direction, fov, depth, short_color) {
    const color = Buffer.alloc(w * h * 3 - (short_color ? 3 : 0), 120);
    let depth_data = Buffer.alloc(0);
    if (depth) {
        const halves = Buffer.alloc(2 * w * h);
        for (let i = 0; i < w * h; i++)
            halves.writeUInt16LE(0x4400, 2 * i); // 4.0 in binary16
        depth_data = zstd_raw(halves);
    }
    return header(TYPE.frame, Buffer.concat([u32(frame_number++), u32(seq), pose(position, direction, fov), u32(w), u32(h),
        Buffer.from([0, depth ? 16 : 0]), u64(0), u64(0), u64(w * h), u64(0), u64(0), f32(1), f32(0), u32(color.length), color,
        u32(depth_data.length), depth_data]));
}

// A samples message answering request 1000000 (never made) with k pixels of the image, red at 4 m.
function unasked_samples(w, h, k) {
    const s = Buffer.alloc(12 * k);
    for (let i = 0; i < k; i++) {
        s.writeUInt16LE((i * 7) % w, 12 * i);
        s.writeUInt16LE((i * 3) % h, 12 * i + 2);
        s[12 * i + 4] = 200;
        s.writeFloatLE(4, 12 * i + 8);
    }
    return header(TYPE.samples, Buffer.concat([u32(1000000), u32(frame_number), pose([0, 1.6, 3], [0, 0, -1], 60), u32(w), u32(h), u32(k), s]));
}

const server = new WebSocket.Server({ host: '127.0.0.1', port: 0 });
server.on('listening', () => console.log(`listening on ws://127.0.0.1:${server.address().port}`));
server.on('connection', ws => {
    let frames = 0, requests = 0;
    ws.on('close', () => process.exit(0));
    ws.on('message', data => {
        const b = Buffer.from(data);
        if (b.length < 12)
            return;
        const type = b.readUInt16LE(6);
        if (type === TYPE.hello) {
            const m = welcome(mode === 'tiny_fps' ? 1e-30 : 30);
            switch (mode) {
            case 'empty': ws.send(Buffer.alloc(0)); return;
            case 'text': ws.send('welcome'); return;
            case 'wrong_type': ws.send(header(99, Buffer.alloc(4))); return;
            case 'len_more': m.writeUInt32LE(m.length, 8); ws.send(m); return;
            case 'len_less': m.writeUInt32LE(m.length - 20, 8); ws.send(m); return;
            case 'frame_first': ws.send(frame(16, 9, 0, [0, 1.6, 3], [0, 0, -1], 60)); return;
            case 'welcome_twice': ws.send(m); ws.send(m); return;
            default: ws.send(m); return;
            }
        }
        if (mode === 'slow_clock' || mode === 'tiny_fps') {
            // One camera (and one sample request) at most: the clock's next is 1e300 s away. A frame for the
            // first camera, then nothing: the viewer waits for its second frame until --timeout.
            if (type === TYPE.camera && frames++ === 0)
                ws.send(frame(16, 9, b.readUInt32LE(12), [0, 1.6, 3], [0, 0, -1], 60, true));
            else if (type === TYPE.camera || (mode === 'tiny_fps' && type === TYPE.sample_request && requests++ > 0))
                ws.send(error(`a flood: a ${type === TYPE.camera ? 'camera' : 'sample request'} after the first`));
            return;
        }
        if (type !== TYPE.camera)
            return;
        const seq = b.readUInt32LE(12);
        if (mode === 'stall' && frames > 0)
            return;
        frames++;
        if (mode === 'nan_camera')
            ws.send(frame(16, 9, seq, [NaN, NaN, NaN], [NaN, NaN, NaN], NaN));
        else
            ws.send(frame(16, 9, seq, [0, 1.6, 3], [0, 0, -1], 60, mode === 'unasked', mode === 'bad_payload'));
        if (mode === 'unasked')
            ws.send(unasked_samples(16, 9, 40));
    });
});
