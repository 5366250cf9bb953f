// The wire format of docs/PROTOCOL.md written out by hand, for the Node peers (tests/peer_ws.js,
// tests/peer_rc_server.js): these are independent of proto/, so the C code is checked against a second
// implementation of the same document.
'use strict';

// Node's `ws` (Debian's node-ws), or exit 77 (ctest's skip) naming the package.
function load_ws(who) {
    for (const where of ['ws', '/usr/share/nodejs/ws', '/usr/lib/nodejs/ws']) {
        try { return require(where); } catch (e) { /* next */ }
    }
    console.error(`${who}: the ws module is missing (Debian package node-ws)`);
    process.exit(77);
}

const TYPE = { hello: 1, welcome: 2, camera: 3, frame: 4, error: 7, bye: 8, sample_request: 9, samples: 10 };

// The 12-byte header ("FXCP", version 1, type, payload length) followed by the payload.
function header(type, payload) {
    const h = Buffer.alloc(12);
    h.write('FXCP', 0, 'latin1');
    h.writeUInt16LE(1, 4);
    h.writeUInt16LE(type, 6);
    h.writeUInt32LE(payload.length, 8);
    return Buffer.concat([h, payload]);
}

// A string with a one-byte length.
function text8(s) {
    const b = Buffer.from(s, 'latin1');
    return Buffer.concat([Buffer.from([b.length]), b]);
}

// A pose: f64 position, f32 direction, f32 vertical field of view in degrees (40 bytes).
function pose(position, direction, fov) {
    const b = Buffer.alloc(40);
    for (let k = 0; k < 3; k++) b.writeDoubleLE(position[k], 8 * k);
    for (let k = 0; k < 3; k++) b.writeFloatLE(direction[k], 24 + 4 * k);
    b.writeFloatLE(fov, 36);
    return b;
}

function read_pose(b, at) {
    const position = [0, 1, 2].map(k => b.readDoubleLE(at + 8 * k));
    const direction = [0, 1, 2].map(k => b.readFloatLE(at + 24 + 4 * k));
    return { position, direction, fov: b.readFloatLE(at + 36), end: at + 40 };
}

module.exports = { load_ws, TYPE, header, text8, pose, read_pose };
