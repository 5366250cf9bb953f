// A fake fxcache server for the viewer client's sample requests (issue 11), not written with our code: Node's
// `ws` (Debian's node-ws) and the wire format written out by hand from docs/PROTOCOL.md.
//
//   node tests/peer_rc_server.js REPORT.json
//
// Listens on 127.0.0.1 (a free port, printed as "listening on ws://127.0.0.1:PORT"), welcomes one viewer,
// sends it no frames, and answers every sample-request at once with a samples message: each requested pixel
// coloured (200, 30, 30) at depth 4 m, with the request's number, camera and size. It checks every request
// (header, sizes, pixels inside the image, the camera finite) and, when the viewer has closed, writes
// REPORT.json: {"requests": n, "pixels": n, "errors": [...], "cameras": [[px, py, pz, dx, dy, dz, fov], ...]}
// and exits 0.
'use strict';

const { load_ws, TYPE, header, text8, pose } = require('./peer_wire.js');
const WebSocket = load_ws('peer_rc_server');
const fs = require('fs');

const report_path = process.argv[2];
const report = { requests: 0, pixels: 0, errors: [], cameras: [] };
setTimeout(() => { report.errors.push('timed out'); finish(); }, 120000).unref();

function finish() {
    fs.writeFileSync(report_path, JSON.stringify(report));
    process.exit(0);
}

// The welcome: viewer 1, "fake_00", 30 fps, the room of the default scene, a camera at (0, 1.6, 3) looking -z.
function welcome() {
    const fps = Buffer.alloc(4);
    fps.writeFloatLE(30, 0);
    const bounds = Buffer.alloc(48);
    [-5, 0, -4, 5, 4, 4].forEach((v, k) => bounds.writeDoubleLE(v, 8 * k));
    const rate = Buffer.alloc(4);
    rate.writeUInt32LE(240, 0);
    const id = Buffer.alloc(4);
    id.writeUInt32LE(1, 0);
    return header(TYPE.welcome, Buffer.concat([id, text8('fake_00'), fps, bounds, pose([0, 1.6, 3], [0, 0, -1], 60), rate]));
}

let answered_frame = 0;
const server = new WebSocket.Server({ host: '127.0.0.1', port: 0 });
server.on('listening', () => console.log(`listening on ws://127.0.0.1:${server.address().port}`));
server.on('connection', ws => {
    ws.on('close', () => finish());
    ws.on('message', (data, is_binary) => {
        const b = Buffer.from(data);
        if (!is_binary || b.length < 12 || b.toString('latin1', 0, 4) !== 'FXCP' || b.readUInt32LE(8) !== b.length - 12) {
            report.errors.push('a message that is not ours');
            return;
        }
        const type = b.readUInt16LE(6);
        if (type === TYPE.hello) {
            ws.send(welcome());
            return;
        }
        if (type !== TYPE.sample_request)
            return; // cameras, bye
        let at = 12;
        const request = b.readUInt32LE(at);
        const camera = b.subarray(at + 4, at + 44);
        const width = b.readUInt32LE(at + 44), height = b.readUInt32LE(at + 48), count = b.readUInt32LE(at + 52);
        at += 56;
        if (b.length !== at + 4 * count) {
            report.errors.push(`request ${request}: ${b.length} bytes for ${count} pixels`);
            return;
        }
        const c = [0, 1, 2].map(k => camera.readDoubleLE(8 * k)).concat([0, 1, 2].map(k => camera.readFloatLE(24 + 4 * k)), [camera.readFloatLE(36)]);
        if (!c.every(Number.isFinite) || count === 0 || width === 0 || height === 0)
            report.errors.push(`request ${request}: camera ${c}, ${width}x${height}, ${count} pixels`);
        if (report.cameras.length < 4096)
            report.cameras.push(c);
        const samples = Buffer.alloc(12 * count);
        for (let i = 0; i < count; i++) {
            const x = b.readUInt16LE(at + 4 * i), y = b.readUInt16LE(at + 4 * i + 2);
            if (x >= width || y >= height)
                report.errors.push(`request ${request}: pixel ${x}, ${y} outside ${width}x${height}`);
            samples.writeUInt16LE(x, 12 * i);
            samples.writeUInt16LE(y, 12 * i + 2);
            samples.writeUInt8(200, 12 * i + 4);
            samples.writeUInt8(30, 12 * i + 5);
            samples.writeUInt8(30, 12 * i + 6);
            samples.writeFloatLE(4, 12 * i + 8);
        }
        const head = Buffer.alloc(8);
        head.writeUInt32LE(request, 0);
        head.writeUInt32LE(answered_frame++, 4);
        const size = Buffer.alloc(12);
        size.writeUInt32LE(width, 0);
        size.writeUInt32LE(height, 4);
        size.writeUInt32LE(count, 8);
        ws.send(header(TYPE.samples, Buffer.concat([head, camera, size, samples])));
        report.requests++;
        report.pixels += count;
    });
});
