// A WebSocket peer not written here: Node's `ws` (Debian's node-ws) talks to `fxcache serve` with the wire
// format written out by hand from docs/PROTOCOL.md, and zstd frames are decoded by the zstd command-line
// tool (the reference implementation), so the server is checked against implementations other than ours.
//
//   node tests/peer_ws.js ws://127.0.0.1:PORT FRAMES WIDTH HEIGHT
//
// Sends hello (zstd, no depth) and a camera every 1/30 s moving around the welcome's default camera,
// receives FRAMES frames, checks every header field and that each payload decodes to WIDTH*HEIGHT*3 bytes
// with some lit pixels, then says bye. Exit 0 on success, 1 with one line on stderr on any failure.
'use strict';

const { load_ws, TYPE, header, text8, pose, read_pose } = require('./peer_wire.js');
const WebSocket = load_ws('peer_ws');
const { execFileSync } = require('child_process');

const [url, frames_arg, width_arg, height_arg] = process.argv.slice(2);
const want_frames = Number(frames_arg || 10), width = Number(width_arg || 160), height = Number(height_arg || 90);

function fail(msg) {
    console.error('peer_ws: ' + msg);
    process.exit(1);
}
setTimeout(() => fail('timed out'), 120000).unref();

function hello() {
    const fixed = Buffer.alloc(15);
    fixed.writeUInt32LE(width, 0);
    fixed.writeUInt32LE(height, 4);
    fixed.writeFloatLE(60, 8);
    fixed.writeUInt8(1, 12); // zstd
    fixed.writeUInt8(0, 13); // no jpeg quality
    fixed.writeUInt8(0, 14); // no depth
    return header(TYPE.hello, Buffer.concat([text8('node-peer'), fixed, text8(''), text8('')]));
}

function camera(sequence, time, p) {
    const head = Buffer.alloc(12);
    head.writeUInt32LE(sequence, 0);
    head.writeDoubleLE(time, 4);
    return header(TYPE.camera, Buffer.concat([head, pose(p.position, p.direction, p.fov), Buffer.from([0])]));
}

const ws = new WebSocket(url);
let welcome = null, received = 0, sequence = 0, timer = null, last_frame = -1;
const start = Date.now();

ws.on('open', () => ws.send(hello()));
ws.on('error', e => fail('connection: ' + e.message));
ws.on('close', (code, reason) => {
    if (received < want_frames) fail(`closed after ${received} frames (${code} ${reason})`);
});
ws.on('message', (data, is_binary) => {
    if (!is_binary) fail('a text message');
    const b = Buffer.from(data);
    if (b.length < 12 || b.toString('latin1', 0, 4) !== 'FXCP') fail('bad magic');
    if (b.readUInt16LE(4) !== 1) fail('version ' + b.readUInt16LE(4));
    const type = b.readUInt16LE(6), length = b.readUInt32LE(8);
    if (length !== b.length - 12) fail(`declared ${length} payload bytes, got ${b.length - 12}`);
    if (type === TYPE.error) fail(`server error ${b.readInt32LE(12)}: ${b.toString('latin1', 18, 18 + b.readUInt16LE(16))}`);
    if (type === TYPE.welcome) {
        let at = 12;
        const id = b.readUInt32LE(at); at += 4;
        const name_len = b.readUInt8(at); const name = b.toString('latin1', at + 1, at + 1 + name_len); at += 1 + name_len;
        const fps = b.readFloatLE(at); at += 4 + 48;
        const cam = read_pose(b, at);
        if (!id || !/^viewer_\d\d/.test(name) || !(fps > 0)) fail(`bad welcome: id ${id} name ${name} fps ${fps}`);
        welcome = cam;
        timer = setInterval(() => {
            const a = 0.02 * sequence;
            const d = welcome.direction;
            const direction = [d[0] * Math.cos(a) - d[2] * Math.sin(a), d[1], d[0] * Math.sin(a) + d[2] * Math.cos(a)];
            ws.send(camera(sequence++, (Date.now() - start) / 1000, { position: welcome.position, direction, fov: 60 }));
        }, 1000 / 30);
        return;
    }
    if (type !== TYPE.frame) fail('unexpected message type ' + type);
    if (!welcome) fail('a frame before welcome');
    let at = 12;
    const frame = b.readUInt32LE(at), camera_sequence = b.readUInt32LE(at + 4); at += 8;
    at = read_pose(b, at).end;
    const w = b.readUInt32LE(at), h = b.readUInt32LE(at + 4), codec = b.readUInt8(at + 8), depth = b.readUInt8(at + 9);
    at += 10;
    const pixels_visible = Number(b.readBigUInt64LE(at + 16));
    at += 5 * 8 + 8;
    const color_bytes = b.readUInt32LE(at); at += 4;
    const color = b.subarray(at, at + color_bytes); at += color_bytes;
    const depth_bytes = b.readUInt32LE(at); at += 4 + depth_bytes;
    if (at !== b.length) fail(`frame fields end at ${at}, message has ${b.length} bytes`);
    if (w !== width || h !== height || codec !== 1 || depth !== 0 || depth_bytes !== 0)
        fail(`frame ${w}x${h} codec ${codec} depth ${depth}`);
    if (frame <= last_frame) fail(`frame numbers go back: ${frame} after ${last_frame}`);
    if (camera_sequence >= sequence) fail(`frame for camera ${camera_sequence}, only ${sequence} sent`);
    last_frame = frame;
    const rgb = execFileSync('zstd', ['-d', '-c', '-q'], { input: color });
    if (rgb.length !== w * h * 3) fail(`zstd payload decodes to ${rgb.length} bytes, want ${w * h * 3}`);
    let lit = 0;
    for (let i = 0; i < rgb.length; i += 3) if (rgb[i] + rgb[i + 1] + rgb[i + 2] > 30) lit++;
    if (lit < w * h / 20 || pixels_visible === 0) fail(`frame ${frame}: ${lit} lit pixels, ${pixels_visible} visible`);
    if (++received === want_frames) {
        clearInterval(timer);
        ws.send(header(TYPE.bye, Buffer.from([2, 0, 0x6f, 0x6b]))); // reason "ok"
        ws.close(1000, 'done');
        console.log(`peer_ws: ${received} frames of ${w}x${h}, zstd payloads decoded by the zstd tool`);
        setTimeout(() => process.exit(0), 100);
    }
});
