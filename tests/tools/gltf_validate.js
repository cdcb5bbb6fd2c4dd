// Validate GLB files with the Khronos glTF-Validator (npm `gltf-validator`); used by tests/motion.
// Usage: NODE_PATH=<dir>/node_modules node gltf_validate.js FILE...
// Prints one JSON line per file: {"file", "errors", "warnings", "infos", "messages": [...]}.
const fs = require('fs');
const validator = require('gltf-validator');

async function main() {
  for (const file of process.argv.slice(2)) {
    const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(file)), {
      maxIssues: 100,
      externalResourceFunction: () => Promise.reject(new Error('no external resources')),
    });
    const issues = report.issues;
    console.log(JSON.stringify({
      file,
      errors: issues.numErrors,
      warnings: issues.numWarnings,
      infos: issues.numInfos,
      messages: issues.messages.map((m) => ({code: m.code, severity: m.severity, pointer: m.pointer, message: m.message})),
    }));
  }
}
main().catch((err) => { console.error(String(err)); process.exit(1); });
