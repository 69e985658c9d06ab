/*
 * drivecheck SITL shim: stand-ins for the board's hardware drivers (our own code). The
 * firmware's drivers for these (CAN, u-blox, servo PWM, IMU over I2C, radios, logging, ADC,
 * hydraulics) are not compiled; these functions take their place with the same names and
 * ABI-compatible parameters (enums as int, opaque struct pointers as void *), so this file needs
 * none of the tree's headers.
 *
 * Where the firmware receives data, the host supplies it (sitl_io.c); where the firmware drives
 * an actuator, the host is told. Everything else is accepted and ignored, or reads as idle.
 */
#include "sitl.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

/* ---- LEDs, logging, ADC, ESC PWM, radios, hydraulics: ignored ---- */

void led_write(int num, int state) {
  (void)num;
  (void)state;
}
void log_set_rate(int rate_hz) { (void)rate_hz; }
void log_set_enabled(bool enabled) { (void)enabled; }
void log_set_name(char *name) { (void)name; }
void log_set_ext(int mode, int baud) {
  (void)mode;
  (void)baud;
}

static float vin = 0.0f;
void sitl_hw_set_vin(float v) { vin = v; }
/* The board's supply voltage: the one the host gives with the motor values. */
float adconv_get_vin(void) { return vin; }

void pwm_esc_set(uint8_t id, float pulse_width) {
  (void)id;
  (void)pulse_width;
}
void pwm_esc_set_all(float pulse_width) { (void)pulse_width; }

bool comm_cc1120_init_done(void) { return false; }
void comm_cc1120_send_buffer(uint8_t *data, unsigned int len) {
  (void)data;
  (void)len;
}
bool cc1120_init_done(void) { return false; }
char *cc1120_state_name(void) { return (char *)"absent (SITL)"; }
void cc1120_update_rf(int set) { (void)set; }

void hydraulic_move(int pos, int move) {
  (void)pos;
  (void)move;
}

/* ---- CAN: the VESC (bldc_interface, see sitl_fw.c), UWB (DW) modules and the IO board ---- */

static int vesc_id;
void comm_can_set_vesc_id(int id) { vesc_id = id; }
int sitl_hw_vesc_id(void) { return vesc_id; }

static void (*range_func)(uint8_t id, uint8_t dest, float range);
void comm_can_set_range_func(void (*func)(uint8_t id, uint8_t dest, float range)) {
  range_func = func;
}
/* A range request: the host answers later (UWB_RANGE), never from inside this call: the
 * firmware's UWB thread calls this holding its position mutex, which the answer locks. */
void comm_can_dw_range(uint8_t id, uint8_t dest, int samples) {
  sitl_out_uwb_request(id, dest, samples);
}
void sitl_hw_deliver_range(uint8_t id, uint8_t dest, float range) {
  if (range_func) range_func(id, dest, range);
}

/* No DW module answers pings or uptime requests. */
static void (*dw_ping_func)(uint8_t id);
static void (*dw_uptime_func)(uint8_t id, uint32_t uptime);
void comm_can_dw_ping(uint8_t id) { (void)id; }
void comm_can_dw_reboot(uint8_t id) { (void)id; }
void comm_can_dw_get_uptime(uint8_t id) { (void)id; }
void comm_can_set_dw_ping_func(void (*func)(uint8_t id)) { dw_ping_func = func; }
void comm_can_set_dw_uptime_func(void (*func)(uint8_t id, uint32_t uptime)) {
  dw_uptime_func = func;
}

/* No IO board on the bus: inputs read zero. */
float comm_can_io_board_adc_voltage(int ch) {
  (void)ch;
  return 0.0f;
}
float comm_can_io_board_as5047_angle(void) { return 0.0f; }
bool comm_can_io_board_lim_sw(int sw) {
  (void)sw;
  return false;
}
static uint8_t adc0_cnt_zero[256];
void *comm_can_io_board_adc0_cnt(void) { return adc0_cnt_zero; }
void comm_can_io_board_set_valve(int board, int valve, bool set) {
  (void)board;
  (void)valve;
  (void)set;
}
void comm_can_io_board_set_pwm_duty(int board, float duty) {
  (void)board;
  (void)duty;
}

/* ---- u-blox: nothing is sent to the receiver; GNSS fixes come as NMEA (sitl_fw.c) ---- */

static void (*ubx_relposned_cb)(void *pos);
static void (*ubx_rawx_cb)(void *rawx);
void ublox_send(unsigned char *data, unsigned int len) {
  (void)data;
  (void)len;
}
void ublox_set_rx_callback_relposned(void (*func)(void *pos)) { ubx_relposned_cb = func; }
void ublox_set_rx_callback_rawx(void (*func)(void *rawx)) { ubx_rawx_cb = func; }

/* ---- steering servo: the board driver's behaviour (servo_simple) ----
 * set_pos moves the output at once; set_pos_ramp sets where a thread at SERVO_RAMP_HZ steps the
 * output, by 1 / (SERVO_RAMP_HZ * steering_ramp_time) of the servo's travel a step (a ramp time
 * of 0 jumps). The output is the physical servo's position: every change goes to the host, and
 * get_pos_now (what pos.c's dead reckoning reads) is it. */

#define SERVO_RAMP_HZ 100
static float servo_pos = 0.5f;
static float servo_target = 0.5f;
static float servo_sent = -1.0f;
static bool servo_started;
static float servo_limit(float pos) {
  if (pos < 0.0f) return 0.0f;
  if (pos > 1.0f) return 1.0f;
  return pos;
}
static void servo_output(void) {
  if (servo_pos != servo_sent) {
    servo_sent = servo_pos;
    sitl_out_servo(servo_pos);
  }
}
void servo_simple_set_pos(float pos) {
  servo_pos = servo_target = servo_limit(pos);
  servo_output();
}
void servo_simple_set_pos_ramp(float pos) { servo_target = servo_limit(pos); }
float servo_simple_get_pos_now(void) { return servo_pos; }
float servo_simple_get_pos_set(void) { return servo_target; }
static THD_WORKING_AREA(servo_thread_wa, 1024);
static THD_FUNCTION(servo_thread, arg) {
  (void)arg;
  chRegSetThreadName("Servo ramp");
  for (;;) {
    float step = 1.0f / ((float)SERVO_RAMP_HZ * sitl_fw_steering_ramp_time());
    if (servo_pos < servo_target) {
      servo_pos = servo_pos + step < servo_target ? servo_pos + step : servo_target;
    } else if (servo_pos > servo_target) {
      servo_pos = servo_pos - step > servo_target ? servo_pos - step : servo_target;
    }
    servo_output();
    chThdSleep(CH_CFG_ST_FREQUENCY / SERVO_RAMP_HZ);
  }
}
void sitl_hw_servo_start(void) {
  if (servo_started) return;
  servo_started = true;
  servo_simple_set_pos(0.5f);
  chThdCreateStatic(servo_thread_wa, sizeof(servo_thread_wa), NORMALPRIO, servo_thread, NULL);
}

/* ---- the IMU: samples at its rate, the values the host last gave (sample and hold) ---- */

static float imu_acc[3], imu_gyro[3], imu_mag[3];
/* the sample being delivered: the held values plus the sensor noise, if the host asked for it */
static float smp_acc[3], smp_gyro[3], smp_mag[3];
static float noise_acc_sd, noise_gyro_sd;
static uint64_t noise_state = 1;
static int imu_rate_hz = 1000; /* the MPU-9150 driver's 1 kHz; the BMI160's is set by init */
static bool imu_started;
#if SITL_IMU_CB_NOARGS
static void (*imu_cb_noargs)(void);
#endif
static void (*imu_cb)(float *accel, float *gyro, float *mag);
static THD_WORKING_AREA(imu_thread_wa, 2048);

void sitl_hw_imu_set(const float accel[3], const float gyro[3], const float mag[3]) {
  memcpy(imu_acc, accel, sizeof imu_acc);
  memcpy(imu_gyro, gyro, sizeof imu_gyro);
  memcpy(imu_mag, mag, sizeof imu_mag);
}

/* Deterministic white noise: xorshift64*, four uniforms summed (unit variance, near Gaussian).
 * A real IMU is never noise-free; perfectly constant data make the firmware's Madgwick filter
 * normalise a zero gradient (0/0) and its attitude NaN. */
void sitl_hw_imu_noise(float accel_sd, float gyro_sd, uint64_t seed) {
  noise_acc_sd = accel_sd;
  noise_gyro_sd = gyro_sd;
  noise_state = seed ? seed : 1;
}

static float unit_noise(void) {
  float sum = 0.0f;
  for (int i = 0; i < 4; i++) {
    noise_state ^= noise_state >> 12;
    noise_state ^= noise_state << 25;
    noise_state ^= noise_state >> 27;
    uint64_t r = noise_state * 0x2545F4914F6CDD1DULL;
    sum += (float)(r >> 40) / 16777216.0f - 0.5f;
  }
  return sum * 1.7320508f;
}

/* The host gives the magnetometer as the firmware sees it after its own treatment of the raw
 * reading (pos.c: the default calibration, identity; X and Y swapped "to match the
 * accelerometer"; the board's yaw rotation). The sensor's raw reading is that undone: rotated
 * back, then swapped. (Zero stays zero.) */
static void raw_mag(const float car[3], float raw[3]) {
  float rot = sitl_fw_board_yaw_rot_deg() * (float)M_PI / 180.0f;
  float c = cosf(rot), s = sinf(rot);
  float sw0 = c * car[0] - s * car[1];
  float sw1 = s * car[0] + c * car[1];
  raw[0] = sw1;
  raw[1] = sw0;
  raw[2] = car[2];
}

static void take_sample(void) {
  for (int i = 0; i < 3; i++) {
    smp_acc[i] = imu_acc[i] + (noise_acc_sd > 0.0f ? noise_acc_sd * unit_noise() : 0.0f);
    smp_gyro[i] = imu_gyro[i] + (noise_gyro_sd > 0.0f ? noise_gyro_sd * unit_noise() : 0.0f);
  }
  raw_mag(imu_mag, smp_mag);
}

static THD_FUNCTION(imu_thread, arg) {
  (void)arg;
  chRegSetThreadName("SitlImu");
  uint64_t k = 0;
  uint64_t t0 = sitl_rt_now_us();
  for (;;) {
    k++;
    uint64_t due = t0 + (k * 1000000ULL) / (uint64_t)imu_rate_hz;
    uint64_t now = sitl_rt_now_us();
    if (due > now) {
      /* whole ticks, as a driver sleeping on the kernel's timer would */
      uint64_t d_ticks = ((due - now) * CH_CFG_ST_FREQUENCY + 999999ULL) / 1000000ULL;
      chThdSleep((systime_t)(d_ticks ? d_ticks : 1));
    }
    take_sample();
#if SITL_IMU_CB_NOARGS
    if (imu_cb_noargs) imu_cb_noargs();
#endif
    if (imu_cb) {
      /* copies: the firmware scales the arrays in place */
      float a[3], g[3], m[3];
      memcpy(a, smp_acc, sizeof a);
      memcpy(g, smp_gyro, sizeof g);
      memcpy(m, smp_mag, sizeof m);
      imu_cb(a, g, m);
    }
  }
}

static void imu_start(void) {
  if (imu_started) return;
  imu_started = true;
  chThdCreateStatic(imu_thread_wa, sizeof(imu_thread_wa), NORMALPRIO + 1, imu_thread, NULL);
}

void mpu9150_init(void) {}
bool mpu9150_is_mpu9250(void) { return false; }
void mpu9150_sample_gyro_offsets(uint32_t iterations) { (void)iterations; }
void mpu9150_get_accel_gyro_mag(float *accel, float *gyro, float *mag) {
  memcpy(accel, smp_acc, sizeof smp_acc);
  memcpy(gyro, smp_gyro, sizeof smp_gyro);
  memcpy(mag, smp_mag, sizeof smp_mag);
}
#if SITL_IMU_CB_NOARGS
void mpu9150_set_read_callback(void (*func)(void)) {
  imu_cb_noargs = func;
  imu_start();
}
#else
void mpu9150_set_read_callback(void (*func)(float *accel, float *gyro, float *mag)) {
  imu_cb = func;
  imu_start();
}
#endif
void bmi160_wrapper_init(int samp_rate_hz) {
  if (samp_rate_hz > 0) imu_rate_hz = samp_rate_hz;
}
void bmi160_wrapper_set_read_callback(void (*func)(float *accel, float *gyro, float *mag)) {
  imu_cb = func;
  imu_start();
}
