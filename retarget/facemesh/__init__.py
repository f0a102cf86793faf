"""MediaPipe's 468-point face mesh run natively (LiteRT), without a browser.

The two models come from the npm package ``@mediapipe/face_mesh`` that the web app already
uses (`retarget.facemesh.assets` extracts them; they ship in this package, Apache-2.0, see
``models/NOTICE``), so the browser's tracker and this one run the same networks.
"""
