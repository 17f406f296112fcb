"""Checks shared by the report and display tests: a failure list, a PNG's size from its IHDR,
and what the display's frames show (linear colours, the tool's steel blue)."""
import struct

failures = []


def check(cond, what):
    if not cond:
        failures.append(what)
        print("FAIL:", what)


def png_size(path):
    """(width, height) from a PNG's IHDR chunk, or None when the file is not a PNG."""
    with open(path, "rb") as f:
        head = f.read(24)
    if head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        return None
    return struct.unpack(">II", head[16:24])


def linear_rgb(img):
    """The RGB of an sRGB image (floats in 0..1, as matplotlib reads a PNG) in linear terms: the
    display's frames are sRGB images of linear colours, and colours compare in linear terms."""
    srgb = img[..., :3].astype(float)
    rgb = ((srgb + 0.055) / 1.055) ** 2.4
    rgb[srgb <= 0.04045] = srgb[srgb <= 0.04045] / 12.92
    return rgb


def tool_blue(rgb):
    """Pixels of the tool's steel blue (0.45, 0.55, 0.70 or the probe's 0.17, 0.26, 0.45, times
    a shade) in a linear RGB image: a boolean mask."""
    return (rgb[..., 2] > rgb[..., 0] + 0.08) & (rgb[..., 2] > 0.2)
