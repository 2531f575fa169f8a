// Servant's sensor board: an Arduino (Uno, Nano, Leonardo...) streaming motion and ambient
// readings as text lines on its USB serial port, 115200 baud. The format is in docs/sensors.md:
//
//   I,<ms>,<ax>,<ay>,<az>,<gx>,<gy>,<gz>   50 a second: acceleration m/s², rotation deg/s
//   A,<ms>,<lux>,<celsius>,<hPa>           2 a second: light, temperature, pressure
//   # ...                                  comments, ignored by Servant
//
// Wiring (I2C: SDA to A4, SCL to A5 on an Uno/Nano; 3.3 V or 5 V as the breakouts allow):
//   MPU-6050 (GY-521) at 0x68, BH1750 light sensor at 0x23, BMP280 at 0x76.
// Without both ambient sensors there are no A lines (a made-up value would be read as a place);
// without the MPU-6050 the board says so in a comment line and stops. Needs the Adafruit BMP280 library (Library Manager).

#include <Wire.h>
#include <Adafruit_BMP280.h>

const uint8_t MPU = 0x68;
const uint8_t BH1750 = 0x23;
const unsigned long IMU_PERIOD_US = 20000UL;      // 50 Hz
const unsigned long AMBIENT_PERIOD_US = 500000UL; // 2 Hz
const float G = 9.80665;
const float ACC_LSB_PER_G = 8192.0;     // +-4 g range
const float GYRO_LSB_PER_DPS = 65.5;    // +-500 deg/s range

Adafruit_BMP280 bmp;
bool haveBmp = false;
bool haveLight = false;
unsigned long nextImu, nextAmbient;

void writeRegister(uint8_t device, uint8_t reg, uint8_t value) {
  Wire.beginTransmission(device);
  Wire.write(reg);
  Wire.write(value);
  Wire.endTransmission();
}

bool present(uint8_t device) {
  Wire.beginTransmission(device);
  return Wire.endTransmission() == 0;
}

void setup() {
  Serial.begin(115200);
  Wire.begin();
  Wire.setClock(400000);
  if (!present(MPU)) {
    Serial.println("# no MPU-6050 at 0x68: check the wiring");
    while (true) {}
  }
  writeRegister(MPU, 0x6B, 0x00);  // wake up
  writeRegister(MPU, 0x1A, 0x04);  // low-pass ~21 Hz: below the 25 Hz Nyquist frequency
  writeRegister(MPU, 0x1B, 0x08);  // gyro +-500 deg/s
  writeRegister(MPU, 0x1C, 0x08);  // accel +-4 g
  haveLight = present(BH1750);
  if (haveLight) {
    Wire.beginTransmission(BH1750);
    Wire.write(0x01);  // power on
    Wire.endTransmission();
    Wire.beginTransmission(BH1750);
    Wire.write(0x10);  // continuous high-resolution mode, 1 lx
    Wire.endTransmission();
  }
  haveBmp = bmp.begin(0x76);
  Serial.println("# servant sensor board: I,ms,ax,ay,az,gx,gy,gz / A,ms,lux,celsius,hpa");
  nextImu = nextAmbient = micros();
}

int16_t readWord() {
  int16_t high = Wire.read();
  return (high << 8) | Wire.read();
}

void sendImu() {
  Wire.beginTransmission(MPU);
  Wire.write(0x3B);  // ACCEL_XOUT_H: accel x,y,z, temperature, gyro x,y,z
  Wire.endTransmission(false);
  if (Wire.requestFrom(MPU, (uint8_t)14) != 14) return;  // a lost reading is a gap, not noise
  float v[6];
  for (int i = 0; i < 3; i++) v[i] = readWord() / ACC_LSB_PER_G * G;
  readWord();  // the chip's own temperature
  for (int i = 3; i < 6; i++) v[i] = readWord() / GYRO_LSB_PER_DPS;
  Serial.print("I,");
  Serial.print(millis());
  for (int i = 0; i < 6; i++) {
    Serial.print(',');
    Serial.print(v[i], 3);
  }
  Serial.println();
}

void sendAmbient() {
  if (!haveLight || !haveBmp) return;
  if (Wire.requestFrom(BH1750, (uint8_t)2) != 2) return;
  uint16_t raw = ((uint16_t)Wire.read() << 8) | Wire.read();
  float lux = raw / 1.2;
  float celsius = bmp.readTemperature();
  float hpa = bmp.readPressure() / 100.0;
  Serial.print("A,");
  Serial.print(millis());
  Serial.print(',');
  Serial.print(lux, 2);
  Serial.print(',');
  Serial.print(celsius, 2);
  Serial.print(',');
  Serial.println(hpa, 2);
}

void loop() {
  unsigned long now = micros();
  if ((long)(now - nextImu) >= 0) {
    nextImu += IMU_PERIOD_US;
    sendImu();
  }
  if ((long)(now - nextAmbient) >= 0) {
    nextAmbient += AMBIENT_PERIOD_US;
    sendAmbient();
  }
}
