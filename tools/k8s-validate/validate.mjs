// Validates Kubernetes manifests against the Kubernetes API's JSON schema (kubernetes-models, the
// OpenAPI schema of Kubernetes 1.27 compiled for ajv): required fields, types, enums and formats.
// Not checked: unknown fields (the API server's strict field validation) and anything a cluster
// decides at admission. Every document of every file is checked; each finding names the file, the
// document's kind and name, and the field.
//   node tools/k8s-validate/validate.mjs deploy/k8s/*.yaml      exit 0 when all are valid, 1 if not
import fs from "node:fs";
import { loadAll } from "js-yaml";

let findings = 0;
const report = (where, message) => {
  console.log(`${where}: ${message}`);
  findings += 1;
};

for (const file of process.argv.slice(2)) {
  let docs;
  try {
    docs = loadAll(fs.readFileSync(file, "utf8"));
  } catch (e) {
    report(file, `not YAML: ${e.message}`);
    continue;
  }
  for (const [index, doc] of docs.entries()) {
    if (doc === null || doc === undefined) continue;
    const where = `${file} [document ${index + 1}] ${doc.kind ?? "?"} ${doc.metadata?.name ?? "?"}`;
    if (typeof doc.apiVersion !== "string" || typeof doc.kind !== "string") {
      report(where, "apiVersion and kind are required");
      continue;
    }
    // apiVersion "apps/v1" -> kubernetes-models/apps/v1, "v1" -> kubernetes-models/v1.
    let Model;
    try {
      Model = (await import(`kubernetes-models/${doc.apiVersion}`))[doc.kind];
    } catch {
      Model = undefined;
    }
    if (typeof Model !== "function") {
      report(where, `no schema for ${doc.apiVersion} ${doc.kind}`);
      continue;
    }
    try {
      new Model(doc).validate();
      console.log(`${where}: valid`);
    } catch (e) {
      report(where, e.message);
    }
  }
}
if (findings > 0) console.log(`${findings} invalid document(s)`);
process.exit(findings > 0 ? 1 : 0);
