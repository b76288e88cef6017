// Reads an MCAP file the way Foxglove does and reports, per topic, what its JSON channels give.
//
//   node check_mcap.mjs LOG.mcap   ->  one JSON document on stdout
//
// The file is read with @mcap/core (Foxglove's MCAP reader). Each json/jsonschema channel's schema
// goes through Foxglove's own parser, `parseJsonSchema` of its mcap-support package, as shipped
// in the npm package @foxglove/studio-base (MPL-2.0; loaded from node_modules at run time, not
// copied here). Every message is then decoded as Foxglove decodes it (JSON.parse, then the
// parser's post-processing: base64 fields to bytes) and checked against the datatypes the
// parser made: each field declared, of the declared kind (number, string, bool, bytes, nested
// message, array). The Python test (tests/replay/test_foxglove_js.py) reads the report.
import { readdirSync, readFileSync, statSync } from "node:fs";
import { open } from "node:fs/promises";
import { createRequire } from "node:module";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";

const require = createRequire(import.meta.url);
const { McapIndexedReader } = require("@mcap/core");
const base64 = require("@protobufjs/base64");

const MARKER = "CONCATENATED MODULE: ../mcap-support/src/parseJsonSchema.ts";

/** Foxglove's parseJsonSchema, taken from the studio-base bundle where it is defined. */
function loadParseJsonSchema() {
  const assets = join(
    dirname(require.resolve("@foxglove/studio-base/package.json")),
    "assets",
  );
  const files = readdirSync(assets)
    .filter((f) => f.endsWith(".js"))
    .map((f) => join(assets, f))
    .sort((a, b) => statSync(a).size - statSync(b).size);
  for (const file of files) {
    const text = readFileSync(file, "utf8");
    const at = text.indexOf(MARKER);
    if (at < 0) continue;
    const start = text.indexOf("function parseJsonSchema(", at);
    const end = text.indexOf("\n// EXTERNAL MODULE", start);
    const source = text.slice(start, end);
    return new Function("base64", `${source}\nreturn parseJsonSchema;`)(base64);
  }
  throw new Error("parseJsonSchema not found in @foxglove/studio-base");
}

/** What a decoded value must be for a field definition; null if it is. */
function problem(value, field, datatypes, path) {
  const check = (v, where) => {
    switch (field.type) {
      case "float64":
      case "uint32":
        return typeof v === "number" ? null : `${where}: expected a number`;
      case "bool":
        return typeof v === "boolean" ? null : `${where}: expected a boolean`;
      case "string":
        return typeof v === "string" ? null : `${where}: expected a string`;
      default: {
        if (v === null || typeof v !== "object" || Array.isArray(v)) {
          return `${where}: expected an object of ${field.type}`;
        }
        return messageProblems(v, field.type, datatypes, where)[0] ?? null;
      }
    }
  };
  if (field.isArray && field.type === "uint8") {
    return value instanceof Uint8Array ? null : `${path}: expected bytes`;
  }
  if (field.isArray) {
    if (!Array.isArray(value)) return `${path}: expected an array`;
    for (let i = 0; i < value.length; i++) {
      const p = check(value[i], `${path}[${i}]`);
      if (p) return p;
    }
    return null;
  }
  return check(value, path);
}

function messageProblems(msg, typeName, datatypes, path) {
  const fields = datatypes.get(typeName)?.definitions;
  if (!fields) return [`${path}: no datatype ${typeName}`];
  const byName = new Map(fields.filter((f) => !f.isConstant).map((f) => [f.name, f]));
  const found = [];
  for (const [name, value] of Object.entries(msg)) {
    const field = byName.get(name);
    const where = path ? `${path}.${name}` : name;
    if (!field) {
      found.push(`${where}: not declared in ${typeName}`);
      continue;
    }
    const p = problem(value, field, datatypes, where);
    if (p) found.push(p);
  }
  return found;
}

async function main(path) {
  const handle = await open(path, "r");
  const size = BigInt((await handle.stat()).size);
  const readable = {
    size: async () => size,
    read: async (offset, length) => {
      const buffer = new Uint8Array(Number(length));
      await handle.read(buffer, 0, Number(length), Number(offset));
      return buffer;
    },
  };
  const reader = await McapIndexedReader.Initialize({ readable });
  const parseJsonSchema = loadParseJsonSchema();
  const decoder = new TextDecoder();
  const topics = {};
  const parsers = new Map();
  for (const [id, channel] of reader.channelsById) {
    const schema = reader.schemasById.get(channel.schemaId);
    const entry = {
      schema: schema?.name ?? "",
      schema_encoding: schema?.encoding ?? "",
      message_encoding: channel.messageEncoding,
      messages: 0,
      problems: [],
      datatypes: [],
      first: null,
    };
    topics[channel.topic] = entry;
    if (channel.messageEncoding !== "json" || schema?.encoding !== "jsonschema") {
      entry.problems.push("not a json channel with a jsonschema schema");
      continue;
    }
    try {
      const parsed = parseJsonSchema(JSON.parse(decoder.decode(schema.data)), schema.name);
      parsers.set(id, parsed);
      entry.datatypes = [...parsed.datatypes.keys()];
    } catch (error) {
      entry.problems.push(`schema: ${error.message}`);
    }
  }
  for await (const message of reader.readMessages()) {
    const channel = reader.channelsById.get(message.channelId);
    const entry = topics[channel.topic];
    entry.messages += 1;
    const parsed = parsers.get(message.channelId);
    if (!parsed) continue;
    const schemaName = reader.schemasById.get(channel.schemaId).name;
    const value = parsed.postprocessValue(JSON.parse(decoder.decode(message.data)));
    const found = messageProblems(value, schemaName, parsed.datatypes, "");
    if (found.length > 0 && entry.problems.length < 20) entry.problems.push(...found.slice(0, 5));
    if (entry.first === null) {
      // bytes as their length: what the decoding made of them, short enough to report
      entry.first = JSON.parse(
        JSON.stringify(value, (_k, v) => (v instanceof Uint8Array ? { bytes: v.length } : v)),
      );
    }
  }
  await handle.close();
  process.stdout.write(JSON.stringify({ topics }));
}

if (process.argv[1] === fileURLToPath(import.meta.url)) {
  await main(process.argv[2]);
}
