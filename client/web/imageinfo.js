// What an image file is, read from its first bytes: its format, size, bit depth and channels
// (a PNG's IHDR, a JPEG's start-of-frame), so that the page can say "16-bit RGBA" before
// anything is sent. The browser decodes every image to 8 bits, so this is the only way to
// know what the service will read.

/** PNG colour types (PNG specification, section 11.2.2 IHDR): their channels. */
const PNG_CHANNELS = {
  0: "grey",
  2: "RGB",
  3: "palette",
  4: "grey + alpha",
  6: "RGBA",
};

/** JPEG components by count: 1 grey, 3 colour (YCbCr or RGB), 4 CMYK (or YCCK). */
const JPEG_CHANNELS = { 1: "grey", 3: "RGB", 4: "CMYK" };

/** The bytes read: a PNG's IHDR is at 16..29; a JPEG's frame header is usually well within
 * the first 64 KiB (after its EXIF and ICC segments), else it is looked for no further. */
const HEAD_BYTES = 64 * 1024;

/**
 * ``{format, width, height, bits, channels}`` of a PNG or JPEG file (``bits``: per channel;
 * ``channels``: "grey", "RGB", "RGBA", "grey + alpha", "palette" or "CMYK"), or null where
 * the file is neither (or too short to say).
 */
export async function imageInfo(file) {
  let bytes;
  try {
    bytes = new Uint8Array(await file.slice(0, HEAD_BYTES).arrayBuffer());
  } catch {
    return null; // unreadable (a file gone since it was chosen)
  }
  return pngInfo(bytes) || jpegInfo(bytes);
}

const PNG_SIGNATURE = [0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a];

function pngInfo(bytes) {
  if (bytes.length < 26 || PNG_SIGNATURE.some((b, i) => bytes[i] !== b)) return null;
  const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  // The first chunk is IHDR: length (4), "IHDR" (4), width, height, bit depth, colour type.
  const type = String.fromCharCode(...bytes.subarray(12, 16));
  if (type !== "IHDR") return null;
  const colour = bytes[25];
  return {
    format: "PNG",
    width: view.getUint32(16),
    height: view.getUint32(20),
    bits: bytes[24],
    channels: PNG_CHANNELS[colour] || `colour type ${colour}`,
  };
}

function jpegInfo(bytes) {
  if (bytes.length < 4 || bytes[0] !== 0xff || bytes[1] !== 0xd8) return null;
  let at = 2;
  while (at + 9 < bytes.length) {
    if (bytes[at] !== 0xff) return null; // not at a marker: not a JPEG this reader follows
    const marker = bytes[at + 1];
    if (marker === 0xff) { // fill bytes before a marker
      at += 1;
      continue;
    }
    const length = (bytes[at + 2] << 8) | bytes[at + 3];
    // SOF0..SOF15, except DHT (C4), JPG (C8) and DAC (CC): the frame header.
    if (marker >= 0xc0 && marker <= 0xcf && ![0xc4, 0xc8, 0xcc].includes(marker)) {
      const components = bytes[at + 9];
      return {
        format: "JPEG",
        width: (bytes[at + 7] << 8) | bytes[at + 8],
        height: (bytes[at + 5] << 8) | bytes[at + 6],
        bits: bytes[at + 4],
        channels: JPEG_CHANNELS[components] || `${components} components`,
      };
    }
    at += 2 + length;
  }
  return null;
}

/** "16-bit RGBA" (or "8-bit palette") of an :func:`imageInfo`, "" of null. */
export function depthWords(info) {
  return info ? `${info.bits}-bit ${info.channels}` : "";
}
