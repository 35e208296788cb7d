#include "mc_flow/io/flow_io.h"

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>

#include "mc_flow/core/buffer_layout.h"
#include "mc_flow/core/error.h"

namespace mc_flow {
namespace io {
namespace {

constexpr float kFloMagic = 202021.25f;  // "PIEH" read as a little-endian float

bool hostIsLittleEndian() {
  const std::uint16_t probe = 1;
  std::uint8_t first;
  std::memcpy(&first, &probe, 1);
  return first == 1;
}

void swapBytes4(void* p, std::size_t count) {
  auto* b = static_cast<std::uint8_t*>(p);
  for (std::size_t i = 0; i < count; ++i, b += 4) {
    std::swap(b[0], b[3]);
    std::swap(b[1], b[2]);
  }
}

std::ofstream openForWriting(const std::string& path) {
  std::ofstream out(path, std::ios::binary);
  if (!out) throw FileError("cannot create '" + path + "'");
  return out;
}

std::ifstream openForReading(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError("cannot open '" + path + "' for reading (missing or unreadable)");
  return in;
}

void finishWriting(std::ofstream& out, const std::string& path) {
  out.flush();
  if (!out) throw FileError("error while writing '" + path + "' (disk full or not writable?)");
}

// Writes floats as little endian regardless of the host.
void writeFloatsLe(std::ofstream& out, const float* values, std::size_t count) {
  if (hostIsLittleEndian()) {
    out.write(reinterpret_cast<const char*>(values), std::streamsize(count * sizeof(float)));
  } else {
    std::vector<float> copy(values, values + count);
    swapBytes4(copy.data(), count);
    out.write(reinterpret_cast<const char*>(copy.data()), std::streamsize(count * sizeof(float)));
  }
}

void writeInt32Le(std::ofstream& out, std::int32_t v) {
  if (!hostIsLittleEndian()) swapBytes4(&v, 1);
  out.write(reinterpret_cast<const char*>(&v), 4);
}

void readExactly(std::ifstream& in, void* dst, std::size_t bytes, const std::string& path) {
  in.read(static_cast<char*>(dst), std::streamsize(bytes));
  if (std::size_t(in.gcount()) != bytes)
    throw InputError("'" + path + "' is truncated: expected " + std::to_string(bytes) + " more bytes");
}

// Bytes from the read position to the end of the file (the position is kept).
std::uint64_t bytesLeft(std::ifstream& in) {
  const std::streampos here = in.tellg();
  in.seekg(0, std::ios::end);
  const std::streampos end = in.tellg();
  in.seekg(here);
  return end > here ? std::uint64_t(end - here) : 0;
}

// Refuses a header whose payload is not in the file before anything is allocated for it.
void checkPayload(std::ifstream& in, std::uint64_t width, std::uint64_t height, std::uint64_t channels,
                  const std::string& what) {
  BufferLayout layout;
  layout.width = width;
  layout.height = height;
  layout.channels = channels;
  layout.value_bytes = sizeof(float);
  layout.row_step = width * channels * sizeof(float);  // packed rows; < 2^36 for 32-bit sizes
  layout.available_bytes = bytesLeft(in);
  layout.exact = false;
  checkBufferLayout(layout, what);
}

// Reads one whitespace-delimited token of a PFM header.
std::string headerToken(std::ifstream& in, const std::string& path) {
  std::string token;
  int c;
  while ((c = in.get()) != EOF && std::isspace(c)) {
  }
  while (c != EOF && !std::isspace(c)) {
    token.push_back(char(c));
    c = in.get();
  }
  if (token.empty()) throw InputError("PFM '" + path + "': truncated header");
  return token;  // the single whitespace after the token has been consumed, as the format requires
}

}  // namespace

void writeFlo(const std::string& path, const ImageF& flow) {
  if (flow.channels != 2)
    throw InputError(".flo '" + path + "': flow must have 2 channels, got " + std::to_string(flow.channels));
  std::ofstream out = openForWriting(path);
  const float magic = kFloMagic;
  writeFloatsLe(out, &magic, 1);
  writeInt32Le(out, flow.width);
  writeInt32Le(out, flow.height);
  writeFloatsLe(out, flow.ptr(), flow.data.size());
  finishWriting(out, path);
}

ImageF readFlo(const std::string& path) {
  std::ifstream in = openForReading(path);
  float magic;
  std::int32_t size[2];
  readExactly(in, &magic, 4, path);
  readExactly(in, size, 8, path);
  if (!hostIsLittleEndian()) {
    swapBytes4(&magic, 1);
    swapBytes4(size, 2);
  }
  if (magic != kFloMagic) throw InputError(".flo '" + path + "': bad magic (expected \"PIEH\")");
  if (size[0] <= 0 || size[1] <= 0)
    throw InputError(".flo '" + path + "': implausible size " + std::to_string(size[0]) + "x" +
                     std::to_string(size[1]));
  checkPayload(in, std::uint64_t(size[0]), std::uint64_t(size[1]), 2, ".flo '" + path + "'");
  ImageF flow(size[0], size[1], 2);
  readExactly(in, flow.ptr(), flow.data.size() * sizeof(float), path);
  if (!hostIsLittleEndian()) swapBytes4(flow.ptr(), flow.data.size());
  return flow;
}

void writePfm(const std::string& path, const ImageF& image) {
  if (image.channels != 1 && image.channels != 3)
    throw InputError("PFM '" + path + "': needs 1 or 3 channels, got " + std::to_string(image.channels));
  std::ofstream out = openForWriting(path);
  out << (image.channels == 3 ? "PF" : "Pf") << "\n" << image.width << " " << image.height << "\n-1.0\n";
  const std::size_t row_values = std::size_t(image.width) * image.channels;
  for (int y = image.height - 1; y >= 0; --y) writeFloatsLe(out, image.ptr() + std::size_t(y) * row_values, row_values);
  finishWriting(out, path);
}

ImageF readPfm(const std::string& path) {
  std::ifstream in = openForReading(path);
  const std::string type = headerToken(in, path);
  int channels;
  if (type == "PF")
    channels = 3;
  else if (type == "Pf")
    channels = 1;
  else
    throw InputError("PFM '" + path + "': bad magic '" + type + "' (expected PF or Pf)");
  int width = 0, height = 0;
  double scale = 0;
  try {
    width = std::stoi(headerToken(in, path));
    height = std::stoi(headerToken(in, path));
    scale = std::stod(headerToken(in, path));
  } catch (const std::logic_error&) {
    throw InputError("PFM '" + path + "': malformed header");
  }
  if (width <= 0 || height <= 0 || scale == 0.0 || !std::isfinite(scale))
    throw InputError("PFM '" + path + "': bad header values " + std::to_string(width) + "x" + std::to_string(height) +
                     ", scale " + std::to_string(scale));
  checkPayload(in, std::uint64_t(width), std::uint64_t(height), std::uint64_t(channels), "PFM '" + path + "'");
  const bool file_little_endian = scale < 0;
  ImageF image(width, height, channels);
  const std::size_t row_values = std::size_t(width) * channels;
  for (int y = height - 1; y >= 0; --y)
    readExactly(in, image.ptr() + std::size_t(y) * row_values, row_values * sizeof(float), path);
  if (file_little_endian != hostIsLittleEndian()) swapBytes4(image.ptr(), image.data.size());
  return image;
}

void writeNpy(const std::string& path, const std::vector<std::size_t>& shape, const std::vector<float>& data) {
  std::size_t count = 1;
  for (std::size_t s : shape) count *= s;
  if (count != data.size())
    throw InputError(".npy '" + path + "': shape holds " + std::to_string(count) + " values but " +
                     std::to_string(data.size()) + " were given");
  std::ostringstream dict;
  dict << "{'descr': '<f4', 'fortran_order': False, 'shape': (";
  for (std::size_t i = 0; i < shape.size(); ++i) dict << (i ? ", " : "") << shape[i];
  if (shape.size() == 1) dict << ",";  // Python's one-element tuple
  dict << "), }";
  std::string header = dict.str();
  // magic(6) + version(2) + length(2) + header, terminated by '\n', padded with spaces to a multiple of 64.
  const std::size_t unpadded = 10 + header.size() + 1;
  header.append((64 - unpadded % 64) % 64, ' ');
  header.push_back('\n');
  if (header.size() > 65535) throw InputError(".npy '" + path + "': header too long for format 1.0");

  std::ofstream out = openForWriting(path);
  out.write("\x93NUMPY", 6);
  out.put(char(1));
  out.put(char(0));
  const std::uint16_t len = std::uint16_t(header.size());
  out.put(char(len & 0xff));
  out.put(char(len >> 8));
  out.write(header.data(), std::streamsize(header.size()));
  writeFloatsLe(out, data.data(), data.size());
  finishWriting(out, path);
}

NpyArray readNpy(const std::string& path) {
  std::ifstream in = openForReading(path);
  char magic[6];
  readExactly(in, magic, 6, path);
  if (std::memcmp(magic, "\x93NUMPY", 6) != 0) throw InputError(".npy '" + path + "': bad magic");
  std::uint8_t version[2];
  readExactly(in, version, 2, path);
  std::size_t header_len = 0;
  if (version[0] == 1) {
    std::uint8_t b[2];
    readExactly(in, b, 2, path);
    header_len = b[0] | (std::size_t(b[1]) << 8);
  } else if (version[0] == 2 || version[0] == 3) {
    std::uint8_t b[4];
    readExactly(in, b, 4, path);
    header_len = b[0] | (std::size_t(b[1]) << 8) | (std::size_t(b[2]) << 16) | (std::size_t(b[3]) << 24);
  } else {
    throw InputError(".npy '" + path + "': unsupported format version " + std::to_string(version[0]));
  }
  std::string header(header_len, '\0');
  readExactly(in, header.data(), header_len, path);
  auto field = [&](const std::string& key) {
    const std::size_t k = header.find("'" + key + "'");
    if (k == std::string::npos) throw InputError(".npy '" + path + "': header lacks '" + key + "'");
    std::size_t colon = header.find(':', k);
    if (colon == std::string::npos) throw InputError(".npy '" + path + "': malformed header");
    return colon + 1;
  };
  {
    const std::size_t p = field("descr");
    const std::size_t q1 = header.find('\'', p), q2 = header.find('\'', q1 + 1);
    const std::string descr = header.substr(q1 + 1, q2 - q1 - 1);
    if (descr != "<f4") throw InputError(".npy '" + path + "': dtype '" + descr + "' unsupported (expected '<f4')");
  }
  {
    const std::size_t p = field("fortran_order");
    if (header.compare(header.find_first_not_of(' ', p), 5, "False") != 0)
      throw InputError(".npy '" + path + "': Fortran order unsupported");
  }
  NpyArray array;
  {
    const std::size_t p = field("shape");
    const std::size_t open = header.find('(', p), close = header.find(')', p);
    if (open == std::string::npos || close == std::string::npos)
      throw InputError(".npy '" + path + "': malformed shape");
    std::stringstream dims(header.substr(open + 1, close - open - 1));
    std::string item;
    while (std::getline(dims, item, ',')) {
      if (item.find_first_not_of(" ") == std::string::npos) continue;
      array.shape.push_back(std::stoul(item));
    }
  }
  std::size_t count = 1;
  for (std::size_t s : array.shape) count *= s;
  array.data.resize(count);
  readExactly(in, array.data.data(), count * sizeof(float), path);
  if (!hostIsLittleEndian()) swapBytes4(array.data.data(), count);
  return array;
}

void writeSoftLabelsNpy(const std::string& path, const SoftLabels& labels) {
  const std::size_t n = std::size_t(labels.count), pixels = labels.planeSize();
  std::vector<float> interleaved(pixels * n);
  for (std::size_t i = 0; i < n; ++i) {
    const float* plane = labels.plane(int(i));
    for (std::size_t p = 0; p < pixels; ++p) interleaved[p * n + i] = plane[p];
  }
  writeNpy(path, {std::size_t(labels.height), std::size_t(labels.width), n}, interleaved);
}

SoftLabels readSoftLabelsNpy(const std::string& path) {
  NpyArray array = readNpy(path);
  if (array.shape.size() != 3) throw InputError(".npy '" + path + "': expected shape (H, W, n)");
  SoftLabels labels(int(array.shape[1]), int(array.shape[0]), int(array.shape[2]));
  const std::size_t n = array.shape[2], pixels = labels.planeSize();
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t p = 0; p < pixels; ++p) labels.plane(int(i))[p] = array.data[p * n + i];
  return labels;
}

void writeTextFile(const std::string& path, const std::string& text) {
  std::ofstream out = openForWriting(path);
  out << text;
  finishWriting(out, path);
}

std::string readTextFile(const std::string& path) {
  std::ifstream in = openForReading(path);
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

std::string tumTrajectoryLine(double stamp, const Eigen::Matrix4d& pose) {
  const Eigen::Quaterniond q(Eigen::Matrix3d(pose.topLeftCorner<3, 3>()));
  char line[256];
  std::snprintf(line, sizeof(line), "%.6f %.6f %.6f %.6f %.6f %.6f %.6f %.6f\n", stamp, pose(0, 3), pose(1, 3),
                pose(2, 3), q.x(), q.y(), q.z(), q.w());
  return line;
}

}  // namespace io
}  // namespace mc_flow
