/*
 * drivecheck SITL shim: the executable's main and its host protocol (our own code).
 * The protocol is described in drivecheck's docs/sitl.md. Frames both ways:
 *   [type: u8][length: u32 little-endian][payload: length bytes]
 * Numbers in payloads are little-endian; floats IEEE-754 binary32, times u64 microseconds of
 * virtual time since start.
 */
#define _GNU_SOURCE
#include "sitl.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "conf_general.h"

#define SITL_PROTOCOL_VERSION 1u
#define SITL_MAX_FRAME (1u << 20)

enum {
  H_ADVANCE = 0x01,
  H_CAR_BYTES = 0x02,
  H_IMU = 0x03,
  H_MOTOR_VALUES = 0x04,
  H_NMEA = 0x05,
  H_UWB_RANGE = 0x06,
  H_STATS = 0x07,
  H_IMU_NOISE = 0x08,
  H_PPS = 0x09,
  H_QUIT = 0x0F,
  S_HELLO = 0x80,
  S_ADVANCED = 0x81,
  S_CAR_BYTES = 0x82,
  S_MOTOR = 0x83,
  S_SERVO = 0x84,
  S_UWB_REQUEST = 0x85,
  S_NOTE = 0x86,
  S_STATS = 0x87,
  S_ERROR = 0x8F,
};

static FILE *out; /* the protocol's stdout; fd 1 itself is pointed at stderr */

static void put_u8(uint8_t v) { fputc(v, out); }
static void put_u32(uint32_t v) {
  uint8_t b[4] = {(uint8_t)v, (uint8_t)(v >> 8), (uint8_t)(v >> 16), (uint8_t)(v >> 24)};
  fwrite(b, 1, 4, out);
}
static void put_u64(uint64_t v) {
  put_u32((uint32_t)v);
  put_u32((uint32_t)(v >> 32));
}
static void put_f32(float f) {
  uint32_t v;
  memcpy(&v, &f, 4);
  put_u32(v);
}
static void frame_head(uint8_t type, uint32_t len) {
  put_u8(type);
  put_u32(len);
}

_Noreturn void sitl_fatal(const char *msg) {
  size_t n = strlen(msg);
  if (out) {
    frame_head(S_ERROR, (uint32_t)n);
    fwrite(msg, 1, n, out);
    fflush(out);
  }
  fprintf(stderr, "sitl: fatal: %s\n", msg);
  exit(2);
}

void sitl_out_car_bytes(const unsigned char *data, unsigned int len) {
  frame_head(S_CAR_BYTES, 8u + len);
  put_u64(sitl_rt_now_us());
  fwrite(data, 1, len, out);
}
void sitl_out_servo(float pos) {
  frame_head(S_SERVO, 12);
  put_u64(sitl_rt_now_us());
  put_f32(pos);
}
void sitl_out_motor(uint8_t kind, float value) {
  frame_head(S_MOTOR, 13);
  put_u64(sitl_rt_now_us());
  put_u8(kind);
  put_f32(value);
}
void sitl_out_uwb_request(uint8_t id, uint8_t dest, int32_t samples) {
  frame_head(S_UWB_REQUEST, 14);
  put_u64(sitl_rt_now_us());
  put_u8(id);
  put_u8(dest);
  put_u32((uint32_t)samples);
}
void sitl_out_note(const char *text) {
  size_t n = strlen(text);
  frame_head(S_NOTE, (uint32_t)(8 + n));
  put_u64(sitl_rt_now_us());
  fwrite(text, 1, n, out);
}

static uint32_t get_u32(const uint8_t *p) {
  return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}
static uint64_t get_u64(const uint8_t *p) { return (uint64_t)get_u32(p) | ((uint64_t)get_u32(p + 4) << 32); }
static float get_f32(const uint8_t *p) {
  uint32_t v = get_u32(p);
  float f;
  memcpy(&f, &v, 4);
  return f;
}

/* The host's frames, read from stdin as many at a time as have arrived (the host writes a
 * step's frames at once): one read(2) a step instead of two a frame. */
static uint8_t inbuf[1 << 16];
static size_t in_pos, in_len;

static bool read_exact(uint8_t *buf, size_t n) {
  size_t got = 0;
  while (got < n) {
    if (in_pos == in_len) {
      ssize_t r = read(0, inbuf, sizeof inbuf);
      if (r <= 0) return false;
      in_pos = 0;
      in_len = (size_t)r;
    }
    size_t take = in_len - in_pos;
    if (take > n - got) take = n - got;
    memcpy(buf + got, inbuf + in_pos, take);
    in_pos += take;
    got += take;
  }
  return true;
}

static void bad_frame(const char *what, uint8_t type, uint32_t len) {
  char msg[160];
  snprintf(msg, sizeof msg, "bad frame: %s (type 0x%02x, length %u)", what, type, len);
  sitl_fatal(msg);
}

int main(void) {
  /* The protocol gets the real stdout; anything else written to fd 1 goes to stderr. */
  int proto_fd = dup(1);
  if (proto_fd < 0 || dup2(2, 1) < 0) {
    fprintf(stderr, "sitl: cannot set up stdout\n");
    return 2;
  }
  out = fdopen(proto_fd, "wb");
  if (!out) return 2;
  static char outbuf[1 << 16];
  setvbuf(out, outbuf, _IOFBF, sizeof outbuf);

  frame_head(S_HELLO, 10);
  put_u32(SITL_PROTOCOL_VERSION);
  put_u8((uint8_t)FW_VERSION_MAJOR);
  put_u8((uint8_t)FW_VERSION_MINOR);
  put_u32((uint32_t)CH_CFG_ST_FREQUENCY);
  fflush(out);

  sitl_hw_start();

  uint8_t *buf = malloc(SITL_MAX_FRAME + 1);
  if (!buf) sitl_fatal("out of memory");
  for (;;) {
    uint8_t head[5];
    if (!read_exact(head, 5)) break; /* the host closed stdin: done */
    uint8_t type = head[0];
    uint32_t len = get_u32(head + 1);
    if (len > SITL_MAX_FRAME) bad_frame("too long", type, len);
    if (!read_exact(buf, len)) bad_frame("truncated", type, len);
    buf[len] = 0;
    switch (type) {
      case H_ADVANCE:
        if (len != 8) bad_frame("ADVANCE wants 8 bytes", type, len);
        sitl_rt_run_until(get_u64(buf));
        frame_head(S_ADVANCED, 8);
        put_u64(sitl_rt_now_us());
        fflush(out);
        break;
      case H_CAR_BYTES:
        sitl_hw_car_bytes(buf, len);
        break;
      case H_IMU: {
        if (len != 36) bad_frame("IMU wants 36 bytes", type, len);
        float v[9];
        for (int i = 0; i < 9; i++) v[i] = get_f32(buf + 4 * i);
        sitl_hw_imu_set(v, v + 3, v + 6);
      } break;
      case H_MOTOR_VALUES: {
        if (len != 24) bad_frame("MOTOR_VALUES wants 24 bytes", type, len);
        float v[6];
        for (int i = 0; i < 6; i++) v[i] = get_f32(buf + 4 * i);
        sitl_hw_motor_values(v);
      } break;
      case H_NMEA:
        sitl_hw_nmea((const char *)buf, len);
        break;
      case H_UWB_RANGE:
        if (len != 6) bad_frame("UWB_RANGE wants 6 bytes", type, len);
        sitl_hw_uwb_range(buf[0], buf[1], get_f32(buf + 2));
        break;
      case H_IMU_NOISE:
        if (len != 16) bad_frame("IMU_NOISE wants 16 bytes", type, len);
        sitl_hw_imu_noise(get_f32(buf), get_f32(buf + 4), get_u64(buf + 8));
        break;
      case H_PPS:
        if (len != 0) bad_frame("PPS has no payload", type, len);
        sitl_hw_pps();
        break;
      case H_STATS:
        frame_head(S_STATS, 16);
        put_u64(sitl_rt_now_us());
        put_u64(sitl_rt_switches());
        fflush(out);
        break;
      case H_QUIT:
        fflush(out);
        return 0;
      default:
        bad_frame("unknown type", type, len);
    }
  }
  fflush(out);
  return 0;
}
