// Writes the Foxglove JSON Schemas that bearing-slam logs use into data_schemas/foxglove/,
// unchanged, from the npm package @foxglove/schemas (MIT): `npm install && node vendor_schemas.mjs`.
// tests/foxglove_js/test_vendored (Python) checks that the files match the package.
import { writeFileSync } from "node:fs";
import { createRequire } from "node:module";

const require = createRequire(import.meta.url);
const schemas = require("@foxglove/schemas/jsonschema");

export const USED = [
  "CompressedImage",
  "FrameTransform",
  "Log",
  "PointCloud",
  "PosesInFrame",
  "RawImage",
  "SceneUpdate",
];

for (const name of USED) {
  const path = new URL(`../../data_schemas/foxglove/foxglove.${name}.json`, import.meta.url);
  writeFileSync(path, JSON.stringify(schemas[name], null, 2) + "\n");
}
