/* TSDF integration: one work item per voxel of the blocks a frame touched.
 * Built after camera_model_shared.h and tsdf_shared.h (the same functions the
 * C++ integrator calls). voxels (and greys, their intensities) hold the
 * touched blocks back to back; image is the grey image, read only when
 * has_image != 0. */
__kernel void integrate_blocks(__global struct FmVoxel* voxels, __global uchar* greys,
                               __global const int* block_coords, __global const float* depth,
                               __global const uchar* image, const int has_image, __global const struct FmCameraT* cam_in,
                               __global const float* pose, const float voxel_size, const float mu,
                               const float max_weight, const float obs_weight, __global int* changed) {
  const int gid = get_global_id(0);
  const int blk = gid / FM_BLOCK_VOXELS;
  const int l = gid - blk * FM_BLOCK_VOXELS;
  const int i = l % FM_BLOCK_SIDE;
  const int j = (l / FM_BLOCK_SIDE) % FM_BLOCK_SIDE;
  const int k = l / (FM_BLOCK_SIDE * FM_BLOCK_SIDE);
  FmCamera cam = *cam_in;
  float T[12];
  for (int n = 0; n < 12; ++n) {
    T[n] = pose[n];
  }
  const float px = (block_coords[3 * blk] * FM_BLOCK_SIDE + i + 0.5f) * voxel_size;
  const float py = (block_coords[3 * blk + 1] * FM_BLOCK_SIDE + j + 0.5f) * voxel_size;
  const float pz = (block_coords[3 * blk + 2] * FM_BLOCK_SIDE + k + 0.5f) * voxel_size;
  __global const uchar* img = has_image ? image : (__global const uchar*)0;
  if (fm_tsdf_integrate_voxel(&voxels[gid], &greys[gid], px, py, pz, &cam, T, depth, img, mu, max_weight, obs_weight)) {
    changed[blk] = 1;
  }
}
