// Bundles src/viewer.js (and zenoh-ts with its WebAssembly) into one self-contained ES module,
// dist/viewer.js, which grains-bridge serves with the page. Run: npm ci && node build.mjs
import * as esbuild from "esbuild";
import { readFile } from "node:fs/promises";
import { dirname, resolve } from "node:path";
import { fileURLToPath } from "node:url";

const here = dirname(fileURLToPath(import.meta.url));

// zenoh-ts's key expressions are Rust compiled to WebAssembly by wasm-bindgen's "bundler"
// target: the glue `zenoh_keyexpr_wrapper.js` does `import * as wasm from "./…_bg.wasm"` and
// expects that module to be the *instantiated* wasm's exports, while the wasm itself imports
// the `__wbg*`/`__wbindgen_*` functions from the glue's `…_bg.js`. This plugin turns the .wasm
// import into a JS module that imports those glue modules, instantiates the inlined bytes
// with them (top-level await) and re-exports the instance's exports under their names.
const inlineWasm = {
  name: "inline-wasm",
  setup(build) {
    build.onResolve({ filter: /\.wasm$/ }, (args) => ({
      path: resolve(args.resolveDir, args.path),
      namespace: "inline-wasm",
    }));
    build.onLoad({ filter: /.*/, namespace: "inline-wasm" }, async (args) => {
      const bytes = await readFile(args.path);
      const module = new WebAssembly.Module(bytes); // only to list imports and exports
      const importModules = [...new Set(WebAssembly.Module.imports(module).map((i) => i.module))];
      const exportNames = WebAssembly.Module.exports(module).map((e) => e.name);
      for (const name of exportNames) {
        if (!/^[A-Za-z_$][\w$]*$/.test(name)) throw new Error(`${args.path}: export ${name} is not an identifier`);
      }
      const lines = [];
      importModules.forEach((m, i) => lines.push(`import * as imp${i} from ${JSON.stringify(m)};`));
      lines.push(`const b64 = ${JSON.stringify(bytes.toString("base64"))};`);
      lines.push(`const bin = atob(b64), bytes = new Uint8Array(bin.length);`);
      lines.push(`for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);`);
      const imports = importModules.map((m, i) => `${JSON.stringify(m)}: imp${i}`).join(", ");
      lines.push(`const { instance } = await WebAssembly.instantiate(bytes, { ${imports} });`);
      for (const name of exportNames) lines.push(`export const ${name} = instance.exports.${name};`);
      // Resolving the glue imports from the .wasm's own folder makes them the very modules
      // the glue JS imports (one copy of its `wasm` variable in the bundle).
      return { contents: lines.join("\n"), loader: "js", resolveDir: dirname(args.path) };
    });
  },
};

const result = await esbuild.build({
  entryPoints: [resolve(here, "src/viewer.js")],
  outfile: resolve(here, "dist/viewer.js"),
  bundle: true,
  format: "esm",
  platform: "browser",
  target: "es2020",
  // The wasm module's instantiation is a top-level await (ES2022), which every browser that
  // runs ES modules with WebAssembly today supports; the rest is held to ES2020.
  supported: { "top-level-await": true },
  minify: true,
  legalComments: "eof",
  plugins: [inlineWasm],
  logLevel: "info",
  metafile: true,
});
const bytes = Object.values(result.metafile.outputs).reduce((n, o) => n + o.bytes, 0);
console.log(`dist/viewer.js: ${bytes} bytes`);
