"""A small hand-made BVH file with known answers, shared by the BVH tests."""

TWO_JOINTS = """HIERARCHY
ROOT Hips
{
  OFFSET 1.0 2.0 3.0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine
  {
    OFFSET 0.0 10.0 0.0
    CHANNELS 3 Yrotation Xrotation Zrotation
    End Site
    {
      OFFSET 0.0 5.0 0.0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.04
0 0 0 10 20 30 40 50 60
1 2 3 -10 -20 -30 -40 -50 -60
"""
