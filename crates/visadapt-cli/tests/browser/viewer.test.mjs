// The viewer page of `visadapt serve` in headless Chromium (Debian's /usr/bin/chromium,
// driven by playwright-core): load the page, move the light slider, check that the image
// and the report change, hover a pixel, take a screenshot.
//
// VISADAPT_BIN: the visadapt binary (default: target/debug/visadapt of this workspace).
// VISADAPT_SCREENSHOT: where to write the screenshot (default: a temporary folder).
import { test, before, after } from "node:test";
import assert from "node:assert/strict";
import { spawn, execFileSync } from "node:child_process";
import { mkdtempSync, rmSync, statSync } from "node:fs";
import { tmpdir } from "node:os";
import { join, resolve, dirname } from "node:path";
import { fileURLToPath } from "node:url";
import { createInterface } from "node:readline";
import { chromium } from "playwright-core";

const here = dirname(fileURLToPath(import.meta.url));
const bin = process.env.VISADAPT_BIN || resolve(here, "../../../../target/debug/visadapt");
const work = mkdtempSync(join(tmpdir(), "visadapt-browser-"));
const screenshot = process.env.VISADAPT_SCREENSHOT || join(work, "viewer.png");
let server;
let url;
let context;

before(async () => {
  const scene = join(work, "chart.exr");
  execFileSync(bin, ["chart", "--white", "100", "-o", scene], { stdio: "ignore" });
  server = spawn(bin, ["serve", scene, "--port", "0", "--no-open", "--fov", "6.7173"], {
    stdio: ["ignore", "pipe", "inherit"],
  });
  const lines = createInterface({ input: server.stdout });
  url = await new Promise((ok, fail) => {
    server.on("exit", (code) => fail(new Error("visadapt serve exited with " + code)));
    lines.on("line", (line) => {
      const m = line.match(/http:\/\/127\.0\.0\.1:\d+\//);
      if (m) ok(m[0]);
    });
  });
  context = await chromium.launchPersistentContext(join(work, "profile"), {
    executablePath: "/usr/bin/chromium",
    headless: true,
    args: ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking"],
    viewport: { width: 1400, height: 1040 },
  });
});

after(async () => {
  if (context) await context.close();
  if (server) server.kill("SIGINT");
  rmSync(work, { recursive: true, force: true, maxRetries: 3 });
});

// Wait until the page has no request in flight and has shown more than `frames` frames
// and `reports` reports.
async function settled(page, frames, reports) {
  await page.waitForFunction(
    ([f, r]) =>
      document.body.dataset.busy === "0" &&
      Number(document.body.dataset.frames) > f &&
      Number(document.body.dataset.reports) > r,
    [frames, reports],
    { timeout: 60000 },
  );
  return page.evaluate(() => [Number(document.body.dataset.frames), Number(document.body.dataset.reports)]);
}

// Mean sRGB code value of the frame as the page shows it.
function brightness(page) {
  return page.evaluate(() => {
    const img = document.getElementById("frame");
    const c = document.createElement("canvas");
    c.width = img.naturalWidth;
    c.height = img.naturalHeight;
    const g = c.getContext("2d");
    g.drawImage(img, 0, 0);
    const d = g.getImageData(0, 0, c.width, c.height).data;
    let sum = 0;
    for (let i = 0; i < d.length; i += 4) sum += d[i] + d[i + 1] + d[i + 2];
    return sum / (3 * c.width * c.height);
  });
}

const reportText = (page) => page.locator("#report").innerText();

test("the viewer page follows the light slider and inspects pixels", async () => {
  const page = await context.newPage();
  const requests = [];
  const errors = [];
  page.on("request", (r) => requests.push(r.url()));
  page.on("response", (r) => {
    if (r.status() >= 400) errors.push(r.status() + " " + r.url());
  });
  page.on("pageerror", (e) => errors.push(e.message));
  page.on("console", (m) => {
    // Failed requests are reported above with their URL.
    if (m.type() === "error" && !m.text().startsWith("Failed to load resource")) errors.push(m.text());
  });
  await page.goto(url);
  let [frames, reports] = await settled(page, 0, 0);

  // The first report sets the slider to the file's own level: 100 cd/m², the chart's white.
  const start = Number(await page.locator("#level").inputValue());
  assert.ok(Math.abs(start - 2) < 0.01, "slider starts at " + start);
  const img = page.locator("#frame");
  const width = await img.evaluate((i) => i.naturalWidth);
  assert.ok(width > 100 && width <= 807, "preview width " + width);
  const dayReport = await reportText(page);
  const day = await brightness(page);
  assert.match(dayReport, /adaptation/);

  // Moonlight: 10^-1.4 = 0.04 cd/m² (Fig. 11c).
  await page.locator("#level").fill("-1.4");
  [frames, reports] = await settled(page, frames, reports);
  const night = await brightness(page);
  const nightReport = await reportText(page);
  assert.notEqual(nightReport, dayReport);
  assert.ok(night < 0.8 * day, "moonlit frame " + night + " vs daylight " + day);
  assert.match(await page.locator("#level-value").innerText(), /0\.0398 cd\/m²/);
  // The report comes from the server for the same level.
  const api = await (await page.request.get(url + "api/report?peak=0.0398107&fov=6.7173")).json();
  assert.ok(nightReport.includes(api.snellen), nightReport + " lacks " + api.snellen);

  // Hover a pixel: the inspector shows the world and displayed luminances and the JNDs.
  const box = await img.boundingBox();
  await page.mouse.move(box.x + box.width * 0.3, box.y + box.height * 0.6);
  await page.waitForFunction(() => document.getElementById("pixel").innerText.includes("JND"), null, {
    timeout: 60000,
  });
  const pixel = await page.locator("#pixel").innerText();
  assert.match(pixel, /world\s+[\d.e+-]+ cd\/m²/);
  assert.match(pixel, /displayed\s+[\d.e+-]+ cd\/m², sRGB \d+ \d+ \d+/);
  assert.match(pixel, /JND: (visible|invisible)/);

  // The A/B split shows the plain exposure beside the model.
  await page.locator("#split").check();
  [frames, reports] = await settled(page, frames, reports);
  assert.equal(await page.locator("#exposure").isVisible(), true);

  await page.screenshot({ path: screenshot });
  assert.ok(statSync(screenshot).size > 10000);

  // Offline: every request went to the server (or to the page's own blob: URLs).
  const foreign = requests.filter((r) => !r.startsWith(url) && !r.startsWith("blob:"));
  assert.deepEqual(foreign, []);
  assert.deepEqual(errors, []);
  await page.close();
});

test("the time course plays and the clock runs", async () => {
  const page = await context.newPage();
  await page.goto(url);
  let [frames, reports] = await settled(page, 0, 0);
  await page.locator("#fig12b").click();
  await page.waitForFunction(() => Number(document.getElementById("t").value) > 5, null, { timeout: 60000 });
  await page.locator("#play").click(); // pause
  [frames, reports] = await settled(page, frames, reports);
  const clock = await page.locator("#clock").innerText();
  const t = Number(clock.match(/t = ([\d.]+)/)[1]);
  assert.ok(t > 5, clock);
  assert.match(await reportText(page), /t after the switch/);
  assert.match(await reportText(page), /rod threshold now/);
  await page.close();
});

// Keep the frame's sRGB code values as the page shows them under `name` (in the page).
function keep(page, name) {
  return page.evaluate((name) => {
    const img = document.getElementById("frame");
    const c = document.createElement("canvas");
    c.width = img.naturalWidth;
    c.height = img.naturalHeight;
    const g = c.getContext("2d");
    g.drawImage(img, 0, 0);
    window.kept = window.kept || {};
    window.kept[name] = g.getImageData(0, 0, c.width, c.height).data;
  }, name);
}

// Fraction of the colour samples (alpha left out) of two kept frames that differ by more
// than two code values.
function changed(page, a, b) {
  return page.evaluate(([a, b]) => {
    const [x, y] = [window.kept[a], window.kept[b]];
    if (x.length !== y.length) return 1;
    let n = 0;
    for (let i = 0; i < x.length; i++) if (i % 4 !== 3 && Math.abs(x[i] - y[i]) > 2) n++;
    return n / ((x.length * 3) / 4);
  }, [a, b]);
}

test("glare and local adaptation switch on and off, and the status line says so", async () => {
  const page = await context.newPage();
  const errors = [];
  page.on("response", (r) => {
    if (r.status() >= 400) errors.push(r.status() + " " + r.url());
  });
  page.on("pageerror", (e) => errors.push(e.message));
  await page.goto(url);
  let [frames, reports] = await settled(page, 0, 0);
  // Moonlight (Fig. 11c): the level where both matter.
  await page.locator("#level").fill("-1.4");
  [frames, reports] = await settled(page, frames, reports);
  const showing = () => page.locator("#showing").innerText();
  assert.match(await showing(), /global adaptation/);
  assert.match(await showing(), /no glare/);
  assert.equal(await page.locator("#glare").isChecked(), false);
  assert.equal(await page.locator("#adaptation").inputValue(), "global");
  await keep(page, "plain");

  await page.locator("#glare").check();
  [frames, reports] = await settled(page, frames, reports);
  assert.match(await showing(), /veiling glare/);
  assert.match(await showing(), /global adaptation/);
  assert.match(await reportText(page), /veiling glare/);
  await keep(page, "glare");
  const byGlare = await changed(page, "plain", "glare");
  assert.ok(byGlare > 0.01, "glare changed " + byGlare + " of the samples");

  await page.locator("#adaptation").selectOption("local");
  [frames, reports] = await settled(page, frames, reports);
  assert.match(await showing(), /local adaptation/);
  assert.match(await showing(), /veiling glare/);
  assert.match(await reportText(page), /local adaptation/);
  await keep(page, "both");
  const byLocal = await changed(page, "glare", "both");
  assert.ok(byLocal > 0.01, "local adaptation changed " + byLocal + " of the samples");

  // Both off again: the first picture, exactly (no cached result of another setting).
  await page.locator("#glare").uncheck();
  await page.locator("#adaptation").selectOption("global");
  [frames, reports] = await settled(page, frames, reports);
  assert.match(await showing(), /global adaptation.*, no glare/);
  assert.doesNotMatch(await reportText(page), /veiling glare|local adaptation/);
  await keep(page, "again");
  assert.equal(await changed(page, "plain", "again"), 0);
  assert.deepEqual(errors, []);
  await page.close();
});
