// Run the Khronos glTF validator on one file and print its report as JSON (used by tests/test_gltf.py).
import { readFile } from "node:fs/promises";
import validator from "gltf-validator";

const path = process.argv[2];
const data = new Uint8Array(await readFile(path));
const report = await validator.validateBytes(data, { maxIssues: 100 });
console.log(JSON.stringify(report));
