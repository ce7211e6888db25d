// Runs the Khronos glTF validator (npm package gltf-validator) over every
// file named on the command line; prints each file's counts and its errors,
// exits 1 when any file has an error, 0 otherwise.
'use strict';
const fs = require('fs');
const validator = require('gltf-validator');

async function main(files) {
    let failed = 0;
    for (const file of files) {
        const bytes = new Uint8Array(fs.readFileSync(file));
        const report = await validator.validateBytes(bytes, { uri: file, maxIssues: 50 });
        const n = report.issues;
        console.log(`${file}: ${n.numErrors} errors, ${n.numWarnings} warnings, ${n.numInfos} infos`);
        for (const m of n.messages)
            if (m.severity <= 1)
                console.log(`  ${m.severity === 0 ? 'error' : 'warning'} ${m.code} ${m.pointer || ''}: ${m.message}`);
        if (n.numErrors > 0)
            failed++;
    }
    process.exit(failed ? 1 : 0);
}
main(process.argv.slice(2)).catch((e) => { console.error(e); process.exit(2); });
