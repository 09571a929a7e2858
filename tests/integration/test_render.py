"""`motionpipe render` on the real CMU clips: an animated GIF and a PNG film strip that an
independent decoder (Pillow) reads, with the expected frame count and size, the body drawn in its
part colours over a white background, and the panels side by side."""
import os
import subprocess
import tempfile
import unittest

from PIL import Image

MOTIONPIPE = os.environ.get("MOTIONPIPE_BIN", "motionpipe")
HERE = os.path.dirname(os.path.abspath(__file__))
CMU = [os.path.join(HERE, "..", "..", "data", "mocap", "cmu", f"131_0{k}.bvh") for k in (1, 2)]


def colours(image):
    return {c for _, c in image.convert("RGB").getcolors(1 << 20)}


class RenderTest(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.mkdtemp(prefix="motionpipe_render_")

    def run_cli(self, *args, check=True):
        result = subprocess.run([MOTIONPIPE, *args], capture_output=True, text=True, timeout=120)
        if check:
            self.assertEqual(result.returncode, 0, result.stderr)
        return result

    def test_gif_of_two_clips_side_by_side(self):
        out = os.path.join(self.dir, "two.gif")
        self.run_cli("render", *CMU, "--title", "131_01", "--title", "131_02", "--gif-fps", "10", "--fps", "30", "--size", "160", "--out", out)
        gif = Image.open(out)
        self.assertEqual(gif.format, "GIF")
        self.assertEqual(gif.size, (320, 160))
        # 131_02 is the longer clip: 10.4 s at 10 fps.
        self.assertEqual(gif.n_frames, 104)
        gif.seek(50)
        frame = gif.convert("RGB")
        found = colours(frame)
        # Background, the left leg (orange) and the right arm (blue) of the Okabe-Ito-like palette
        # after GIF quantisation (6x6x6 cube): white, (255, 153, 0) and (0, 102, 204).
        self.assertIn((255, 255, 255), found)
        self.assertTrue(any(r > 200 and 100 < g < 200 and b < 60 for r, g, b in found), "no left-leg orange")
        self.assertTrue(any(r < 60 and g < 140 and b > 150 for r, g, b in found), "no right-side blue")
        # Both panels hold a body: coloured pixels left and right of the middle.
        def coloured(x0, x1):
            return sum(1 for x in range(x0, x1) for y in range(20, 150)
                       if (lambda p: max(p) - min(p) > 80)(frame.getpixel((x, y))))
        self.assertGreater(coloured(0, 160), 50)
        self.assertGreater(coloured(160, 320), 50)
        # Frames differ over time (the animation moves).
        gif.seek(0)
        first = gif.convert("RGB").tobytes()
        self.assertNotEqual(first, frame.tobytes())

    def test_png_film_strip_and_bad_output(self):
        out = os.path.join(self.dir, "strip.png")
        self.run_cli("render", CMU[0], "--frames", "5", "--size", "120", "--out", out)
        png = Image.open(out)
        self.assertEqual(png.size, (600, 120))
        self.assertIn((255, 255, 255), colours(png))
        refused = self.run_cli("render", CMU[0], "--out", os.path.join(self.dir, "x.mp4"), check=False)
        self.assertEqual(refused.returncode, 1)
        self.assertIn("mp4 output is not available", refused.stderr)
        refused = self.run_cli("render", CMU[0], "--out", os.path.join(self.dir, "x.jpg"), check=False)
        self.assertIn("must end in .gif", refused.stderr)


if __name__ == "__main__":
    unittest.main()
