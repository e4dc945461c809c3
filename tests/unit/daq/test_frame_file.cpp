// An area detector's frames in NDFileHDF5's default layout, read back with HDF5's C API.
#include "core/error.hpp"
#include "daq/frame_file.hpp"

#include "../temp_dir.hpp"

#include <gtest/gtest.h>
#include <hdf5.h>

#include <cstdint>
#include <string>
#include <vector>

using namespace beamctl;

TEST(FrameFile, FramesAndTheirAttributesInNdFileHdf5sLayout) {
    test::TempDir dir;
    const std::string path = dir.file("cam1_001.h5");
    std::vector<uint16_t> px(6 * 4);
    {
        daq::FrameFile f(path, daq::PixelType::UInt16, 6, 4);
        for (int k = 0; k < 3; ++k) {
            for (std::size_t i = 0; i < px.size(); ++i) px[i] = uint16_t(1000 * k + i);
            f.append(px.data(), daq::PixelType::UInt16, 6, 4, 10 + k, 1e9 + k + 0.25);
        }
        EXPECT_EQ(f.frames(), 3u);
        EXPECT_EQ(f.bytes(), 3u * 48);
        // another size or type is refused, the file keeps its frames
        EXPECT_THROW(f.append(px.data(), daq::PixelType::UInt16, 4, 6, 13, 0), Error);
        EXPECT_THROW(f.append(px.data(), daq::PixelType::Int16, 6, 4, 13, 0), Error);
        f.close();
    }
    hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    ASSERT_GE(file, 0);
    for (const char* link : {"/entry/data/data", "/entry/instrument/detector/data"}) {
        hid_t ds = H5Dopen2(file, link, H5P_DEFAULT);
        ASSERT_GE(ds, 0) << link;
        hid_t space = H5Dget_space(ds);
        hsize_t dims[3] = {};
        ASSERT_EQ(H5Sget_simple_extent_ndims(space), 3);
        H5Sget_simple_extent_dims(space, dims, nullptr);
        EXPECT_EQ(dims[0], 3u);
        EXPECT_EQ(dims[1], 4u);
        EXPECT_EQ(dims[2], 6u);
        std::vector<uint16_t> all(3 * 24);
        ASSERT_GE(H5Dread(ds, H5T_NATIVE_UINT16, H5S_ALL, H5S_ALL, H5P_DEFAULT, all.data()), 0);
        EXPECT_EQ(all[0], 0);
        EXPECT_EQ(all[24 + 5], 1005);
        EXPECT_EQ(all[48 + 23], 2023);
        H5Sclose(space);
        H5Dclose(ds);
    }
    hid_t uid = H5Dopen2(file, "/entry/instrument/NDAttributes/NDArrayUniqueId", H5P_DEFAULT);
    int32_t ids[3] = {};
    ASSERT_GE(H5Dread(uid, H5T_NATIVE_INT32, H5S_ALL, H5S_ALL, H5P_DEFAULT, ids), 0);
    EXPECT_EQ(ids[0], 10);
    EXPECT_EQ(ids[2], 12);
    H5Dclose(uid);
    hid_t ns = H5Dopen2(file, "/entry/instrument/NDAttributes/NDArrayEpicsTSnSec", H5P_DEFAULT);
    uint32_t nsec[3] = {};
    ASSERT_GE(H5Dread(ns, H5T_NATIVE_UINT32, H5S_ALL, H5S_ALL, H5P_DEFAULT, nsec), 0);
    EXPECT_EQ(nsec[1], 250000000u);
    H5Dclose(ns);
    H5Fclose(file);
}

TEST(FrameFile, AFileThatCannotBeCreatedNamesItsPath) {
    try {
        daq::FrameFile f("/nonexistent-dir/x.h5", daq::PixelType::UInt8, 2, 2);
        FAIL() << "no error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("/nonexistent-dir/x.h5"), std::string::npos) << e.what();
    }
}
