// Vite build of the editor: one entry (index.html), hashed assets under dist/assets, served by the backend.
// The backend's API docs page (/docs) gets Swagger UI from dist/docs, copied from the swagger-ui-dist package:
// the product runs offline, so nothing is loaded from a CDN.
import { readFileSync } from "node:fs";
import { createRequire } from "node:module";
import { dirname, join } from "node:path";
import { defineConfig } from "vite";

const SWAGGER_UI_FILES = ["swagger-ui-bundle.js", "swagger-ui.css", "favicon-32x32.png", "LICENSE"];

/** Emit Swagger UI's browser files under dist/docs. */
function swaggerUi() {
  const require = createRequire(import.meta.url);
  const folder = dirname(require.resolve("swagger-ui-dist/package.json"));
  return {
    name: "cama-swagger-ui",
    generateBundle() {
      for (const name of SWAGGER_UI_FILES) {
        this.emitFile({ type: "asset", fileName: `docs/${name}`, source: readFileSync(join(folder, name)) });
      }
    },
  };
}

export default defineConfig({
  base: "/",
  plugins: [swaggerUi()],
  build: {
    outDir: "dist",
    assetsDir: "assets",
    emptyOutDir: true,
    sourcemap: false,
    chunkSizeWarningLimit: 1024,
  },
});
